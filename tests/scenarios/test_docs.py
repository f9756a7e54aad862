"""docs/scenes.md is the schema's own account of itself: regenerated, it is the checked-in page;
every key of every section has a description and an example; the page's example scene is valid."""

from __future__ import annotations

import re
from pathlib import Path

from pydantic import Field

from scenarios.scene import scene_from_dict
from scenarios.scene.reference import COMMAND, missing_documentation, render
from scenarios.scene.schema import Section

REPO = Path(__file__).resolve().parents[2]


def test_scene_reference_is_the_generated_page():
    page = (REPO / "docs" / "scenes.md").read_text(encoding="utf-8")
    assert page == render(), f"docs/scenes.md is stale: regenerate it with `{COMMAND}`"


def test_every_key_has_a_description_and_an_example():
    assert missing_documentation() == []


def test_an_undocumented_key_is_found():
    class Bare(Section):
        documented: float = Field(default=1.0)
        """A documented key [h]."""
        bare_h: float = Field(default=None)

    assert missing_documentation([((), Bare)]) == ["Bare.bare_h: no description", "Bare.bare_h: no example"]


def test_every_section_and_key_of_the_schema_is_on_the_page():
    page = render()
    for name in ("feed_tph", "preview_lead_h", "p80_dead_time_h", "rk4_substeps", "history_max_gap_h",
                 "circulating_load_nominal", "dead_time_h"):
        assert f"| `{name}` |" in page
    row = re.search(r"^\| `solver` \|.*$", page, re.M).group(0)
    assert '"ipopt"' in row and "the default" in row  # IPOPT is the default, and the page says so
    assert re.search(r"^\| `kind` \|.*feed rate only", page, re.M)  # PI moves the feed only


def test_the_pages_example_scene_is_valid():
    import tomllib

    block = re.search(r"```toml\n(.*?)```", render(), re.S).group(1)
    scene = scene_from_dict(tomllib.loads(block), REPO / "scenarios" / "reference_transition.toml")
    assert scene.controller.solver == "rti" and scene.feed.schedule[0].blend == {"B": 0.6, "D": 0.4}


def test_readme_cli_table_lists_every_command():
    from scenarios.cli.commands import COMMANDS

    readme = (REPO / "README.md").read_text(encoding="utf-8")
    table = readme[readme.index("## The CLI"):readme.index("Exit codes:")]
    listed = set(re.findall(r"^\| `grindtwin ([a-z][a-z-]*)", table, re.M))  # commands, not --version
    assert listed == set(COMMANDS), f"README's CLI table: missing {set(COMMANDS) - listed}, extra {listed - set(COMMANDS)}"


def test_readme_cli_table_names_only_options_its_commands_take():
    """A synopsis in README's CLI table naming an option its command does not take (one renamed,
    say) sends a user to an argparse error: every --option of each row's synopsis must be one of
    that command's."""
    import argparse

    from scenarios.cli import build_parser
    from twin.calibration.calibrate import add_arguments

    sub = next(a for a in build_parser()._actions if a.choices and "run" in a.choices)
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    table = readme[readme.index("## The CLI"):readme.index("Exit codes:")]
    parsers = dict(sub.choices)
    # calibrate passes its options through to the calibration's own parser
    parsers["calibrate"] = add_arguments(argparse.ArgumentParser())
    unknown = []
    for command, synopsis in re.findall(r"^\| `grindtwin ([a-z][a-z-]*)([^`]*)`", table, re.M):
        known = {o for a in parsers[command]._actions for o in a.option_strings}
        unknown += [f"{command} {o}" for o in re.findall(r"--[a-z][a-z0-9-]*", synopsis) if o not in known]
    assert unknown == [], f"README's CLI table names options its commands do not take: {unknown}"


def test_help_texts_have_no_doubled_percent_signs():
    from scenarios.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.choices and "run" in a.choices)
    for name, p in sub.choices.items():
        assert "%%" not in p.format_help(), name


def test_readmes_python_example_runs_as_written(capsys):
    """README's python block, executed as a user would paste it: the blend's steady state lies
    inside what the models describe (its one note: the preset mill, sized in a cyclone circuit,
    runs on its grate), and the 8-h run has one row per minute."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    (block,) = re.findall(r"```python\n(.*?)```", readme, re.S)
    ns: dict = {}
    exec(compile(block, "README.md", "exec"), ns)  # noqa: S102 - the README's own example
    (note,) = ns["ss"].notes
    assert note.startswith("mill 'industrial' was sized with a hydrocyclone circuit")
    assert 100.0 < ns["ss"].p80_um < 1000.0
    assert len(ns["run"].frame) == 8 * 60 + 1
    assert "Effects:" in capsys.readouterr().out


def test_the_regeneration_pages_commands_are_those_the_shipped_files_record():
    """docs/regenerate.md: each command parses, and the shipped files' own commands are its."""
    import json
    import shlex

    from scenarios.cli import build_parser

    page = (REPO / "docs" / "regenerate.md").read_text(encoding="utf-8")
    commands = re.findall(r"`(grindtwin [^`]+|python -m [^`]+)`", page)
    parser = build_parser()
    for command in commands:
        words = shlex.split(command)
        if words[0] == "grindtwin" and words[1] in ("calibrate", "size-mill"):
            parser.parse_args(words[1:])  # SystemExit on an unknown option
    recorded = [json.loads((REPO / p).read_text())["provenance"]["command"]
                for p in ("twin/calibration/files/dem.json", "twin/calibration/files/table.json")]
    recorded.append(json.loads((REPO / "twin/data/industrial_mill.json").read_text())["command"])
    for command in recorded:
        assert command in commands, f"docs/regenerate.md does not give {command!r}"
    from twin.surrogate import GENERATE_COMMAND

    assert any(c.startswith(GENERATE_COMMAND) for c in commands)


def test_readme_says_how_a_workbook_writes_an_undefined_number():
    """README said every undefined number of a workbook is Excel's #N/A, where the KPI sheet (a text sheet,
    scenarios.output.workbook.TEXT_SHEETS) leaves its value cell empty beside a note saying why, and a sweep
    case that ran has an empty error cell: the sentence that names #N/A now says which sheets hold it."""
    from scenarios.output.workbook import TEXT_SHEETS, UNDEFINED_NOTE, XLSX_NA

    text = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    assert "KPIs" in TEXT_SHEETS and UNDEFINED_NOTE.startswith("n/a")
    (sentence,) = [s for s in text.split(". ") if f"`{XLSX_NA}`" in s]
    assert "tables of numbers" in sentence and "in a workbook it is Excel's" not in sentence
    assert "KPI sheet" in sentence and "empty value cell whose note says why" in sentence
    assert "empty `error` cell" in sentence
