"""The audit log: complete Parquet parts, read back in order; never written into a foreign folder."""

import math
from datetime import datetime, timezone

import pandas as pd
import pytest

from scenarios.errors import SceneError
from scenarios.online import AuditLog, check_audit_dir, read_audit


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


def test_the_folder_is_made_at_the_first_row(tmp_path):
    a = AuditLog(tmp_path / "new" / "audit", flush_every=2)
    assert not (tmp_path / "new").exists()  # a start that fails before its first cycle leaves nothing behind
    a.record({"cycle": 0})
    a.record({"cycle": 1})
    assert read_audit(tmp_path / "new" / "audit")["cycle"].tolist() == [0, 1]
    assert [p.suffix for p in (tmp_path / "new" / "audit").iterdir()] == [".parquet"]  # the journal went with it


def test_a_crash_loses_no_recorded_row(tmp_path):
    """Rows were kept in memory until flush_every (20) had come: a killed service lost up to 20 cycles, an hour
    of moves at 3-minute samples. A crashed part's journal is read back, beside the parts of a restart."""
    a = AuditLog(tmp_path / "audit", flush_every=20)
    t = datetime(2030, 1, 1, tzinfo=timezone.utc)
    for k in range(3):
        a.record({"wall_time_utc": t, "cycle": k, "p80_um": math.nan if k == 1 else 210.0 + k, "written": k != 1,
                  "mode": "auto"})
    del a  # killed: no flush, no shutdown
    with open(next((tmp_path / "audit").glob("*.jsonl")), "a") as f:
        f.write('{"cycle": 3, "mo')  # the line the kill cut
    check_audit_dir(tmp_path / "audit")  # a restart takes the folder
    b = AuditLog(tmp_path / "audit", flush_every=20)
    b.record({"wall_time_utc": t, "cycle": 0, "p80_um": 200.0, "written": False, "mode": "warmup"})
    b.flush()
    frame = read_audit(tmp_path / "audit")
    assert frame["cycle"].tolist() == [0, 1, 2, 0] and frame["mode"].tolist() == ["auto"] * 3 + ["warmup"]
    assert frame["p80_um"].iloc[0] == 210.0 and math.isnan(frame["p80_um"].iloc[1])
    assert frame["written"].tolist() == [True, False, True, False]
    assert (frame["wall_time_utc"] == pd.Timestamp(t)).all()


def test_reading_an_audit_folder_never_made_says_why(tmp_path):
    """serve makes its audit folder at its first write: a service that wrote no cycle leaves none, and reading it
    raised iterdir's bare FileNotFoundError."""
    with pytest.raises(FileNotFoundError, match="no audit folder there .serve --audit makes it at its first write"):
        read_audit(tmp_path / "never")
