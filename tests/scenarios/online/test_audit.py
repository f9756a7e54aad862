"""The audit log: complete Parquet parts, read back in order; never written into a foreign folder."""

import pytest

from scenarios.errors import SceneError
from scenarios.online import AuditLog, read_audit


def test_rows_come_back_in_order_across_parts_and_restarts(tmp_path):
    a = AuditLog(tmp_path / "audit", flush_every=2)
    for k in range(5):
        a.record({"cycle": k, "reason": f"r{k}"})
    assert len(list((tmp_path / "audit").glob("*.parquet"))) == 2  # 4 rows flushed, 1 pending
    a.flush()
    b = AuditLog(tmp_path / "audit", flush_every=10)  # a restart adds parts beside the old ones
    b.record({"cycle": 5, "reason": "r5"})
    b.flush()
    frame = read_audit(tmp_path / "audit")
    assert frame["cycle"].tolist() == [0, 1, 2, 3, 4, 5]


def test_a_folder_with_other_files_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(SceneError, match="notes.txt"):
        AuditLog(tmp_path)
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_the_folder_is_made_at_the_first_write(tmp_path):
    a = AuditLog(tmp_path / "new" / "audit", flush_every=2)
    a.record({"cycle": 0})
    assert not (tmp_path / "new").exists()  # nothing written yet: a start that fails now leaves nothing behind
    a.record({"cycle": 1})
    assert read_audit(tmp_path / "new" / "audit")["cycle"].tolist() == [0, 1]


def test_reading_an_audit_folder_never_made_says_why(tmp_path):
    """serve makes its audit folder at its first write: a service that wrote no cycle leaves none, and reading it
    raised iterdir's bare FileNotFoundError."""
    with pytest.raises(FileNotFoundError, match="no audit folder there .serve --audit makes it at its first write"):
        read_audit(tmp_path / "never")
