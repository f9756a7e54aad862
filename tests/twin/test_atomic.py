"""Writes beside a user's files touch nothing but their target (twin.atomic)."""

import math
import os
import stat

import numpy as np
import pytest

from tests.conftest import strict_json
from twin.atomic import json_text, new_folder_beside, write_text_atomically
from twin.calibration.files import write_json_atomically


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def test_a_write_leaves_files_named_like_scratch_files_alone(tmp_path):
    target = tmp_path / "cal.json"
    theirs = {tmp_path / "cal.tmp": "a", tmp_path / "cal.json.partial": "b", tmp_path / "cal.json.tmp": "c"}
    for p, text in theirs.items():
        p.write_text(text)
    write_json_atomically(target, {"x": 1})
    write_text_atomically(target, '{"x": 2}\n')  # over an existing target too
    assert target.read_text() == '{"x": 2}\n'
    assert {p: p.read_text() for p in theirs} == theirs
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["cal.json", *(p.name for p in theirs)])


def test_a_failed_write_leaves_the_target_and_no_scratch_file(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")
    with pytest.raises(TypeError):
        write_text_atomically(target, 42)  # not text: fails inside the write
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_written_files_and_folders_get_the_usual_permissions(tmp_path):
    plain = tmp_path / "plain.txt"
    plain.write_text("x")  # what open() gives under this umask
    written = write_text_atomically(tmp_path / "w.txt", "x")
    assert _mode(written) == _mode(plain)
    (tmp_path / "plain").mkdir()
    folder = new_folder_beside(tmp_path / "export")
    assert _mode(folder) == _mode(tmp_path / "plain")
    assert folder.parent == tmp_path and folder != new_folder_beside(tmp_path / "export")


def test_json_text_is_strict_json_that_keeps_what_a_number_means():
    """Undefined (NaN, numpy's too) is null; an infinity, a number, the text inf / -inf (null would make it
    undefined); numpy scalars, tuples and keys as JSON has them."""
    obj = {1: (math.nan, np.float32("nan"), math.inf, -np.inf, np.float64(2.5), np.int64(3), np.bool_(True))}
    assert strict_json(json_text(obj)) == {"1": [None, None, "inf", "-inf", 2.5, 3, True]}
