"""grindtwin serve and plant-server refuse bad input with exit 2 and one line, before anything runs."""

import pytest

from scenarios.cli import main
from scenarios.errors import SceneError

from .conftest import SMALL_TAGS


@pytest.mark.parametrize("argv, message", [
    (["serve", "{scene}", "--opcua", "opc.tcp://127.0.0.1:4840", "--tags", "{tags}"],
     "a secure session needs --cert, --key, --server-cert, --user (or --insecure for an unsecured one)"),
    (["serve", "{scene}", "--opcua", "opc.tcp://127.0.0.1:4840", "--tags", "{tags}", "--insecure", "--user", "apc"],
     "--insecure connects without security or user; drop --user"),
    (["plant-server", "{scene}", "--opcua", "opc.tcp://127.0.0.1:4840", "--tags", "{tags}", "--cert", "c.pem"],
     "a secure endpoint needs --key, --trust, --users"),
    (["serve", "{scene}", "--opcua", "opc.tcp://127.0.0.1:4840", "--tags", "{bad_tags}", "--insecure"],
     "setpoints.feed_tph: min must be below max once the scene's bounds fill the one not given (min 40.0, max 30.0)"),
    (["plant-server", "{scene}", "--opcua", "opc.tcp://127.0.0.1:4840", "--speedup", "0", "--insecure"],
     "--speedup must be in (0, 1e+06]"),
    # serve sat disconnected for ever (its reconnect task dead of asyncua's ValueError); plant-server failed
    # with a traceback after its models
    (["serve", "{scene}", "--opcua", "garbage", "--tags", "{tags}", "--insecure"],
     "--opcua must be an endpoint URL opc.tcp://HOST[:PORT] with a port in [1, 65535]"),
    (["plant-server", "{scene}", "--opcua", "opc.tcp://127.0.0.1:99999", "--insecure"],
     "--opcua must be an endpoint URL opc.tcp://HOST[:PORT] with a port in [1, 65535]"),
])
def test_bad_input_exits_2_with_one_clear_line(small_files, tmp_path, capsys, argv, message):
    scene, tags = small_files
    bad = tmp_path / "bad.toml"
    bad.write_text(SMALL_TAGS.replace('node = "ns=2;s=Mill.Feed.Setpoint_tph"',
                                      'node = "ns=2;s=Mill.Feed.Setpoint_tph"\nmin = 40.0\nmax = 30.0'))
    args = [a.format(scene=scene, tags=tags, bad_tags=bad) for a in argv]
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err


def test_serve_refuses_a_users_audit_folder_before_it_builds_its_models(small_files, tmp_path, capsys, monkeypatch):
    """--audit naming a folder with a user's file was refused only after the estimator and NMPC were built (7 s
    on the small scene); now before, the file left as it was."""
    import scenarios.online as online

    scene, tags = small_files
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("my notes")
    monkeypatch.setattr(online, "build_parts", lambda *a, **k: pytest.fail("models built before the refusal"))
    assert main(["serve", str(scene), "--opcua", "opc.tcp://127.0.0.1:4840", "--tags", str(tags), "--insecure",
                 "--audit", str(folder)]) == 2
    assert "notes.txt" in capsys.readouterr().err and (folder / "notes.txt").read_text() == "my notes"


def test_a_serve_that_fails_building_its_models_leaves_no_audit_folder(small_files, tmp_path, capsys, monkeypatch):
    """The audit folder was made when --audit was checked, before the models were built: a start that failed there
    left an empty folder behind. It is made at the first audit write."""
    import scenarios.online as online

    def fail(*a, **k):
        raise SceneError("the models could not be built")

    scene, tags = small_files
    folder = tmp_path / "new" / "audit"
    monkeypatch.setattr(online, "build_parts", fail)
    assert main(["serve", str(scene), "--opcua", "opc.tcp://127.0.0.1:4840", "--tags", str(tags), "--insecure",
                 "--audit", str(folder)]) == 2
    assert "the models could not be built" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
