"""Sample tables: row-by-row validation, and the synthetic reference library."""

import numpy as np
import pandas as pd
import pytest

from twin.errors import TwinInputError
from twin.ore.sample_library import (COUNTS, DEPOSIT_RANGES, TABLE1_RANGES, generate_library,
                                 load_reference_samples, main)
from twin.ore.samples import (SampleTableError, read_header_comments, read_samples, to_mineralogies,
                          validate_samples)


def _table():
    return pd.DataFrame({
        "sample_id": ["S1", "S2", "S3"],
        "quartz_wt_pct": [60.0, 40.0, 25.0],
        "kaolinite_wt_pct": [5.0, 30.0, 35.0],
        "pyrite_wt_pct": [35.0, 30.0, 40.0],
        "mean_grain_um": [200.0, 100.0, 50.0],
        "uniformity": [0.8, 0.6, 0.4],
        "association_entropy": [0.3, 0.5, 0.8],
    })


def test_valid_table_round_trips_csv_and_parquet(tmp_path):
    t = _table()
    p = tmp_path / "s.csv"
    p.write_text("# provenance line\n" + t.to_csv(index=False))
    got = read_samples(p)
    assert list(got.sample_id) == ["S1", "S2", "S3"]
    assert read_header_comments(p) == ["provenance line"]
    q = tmp_path / "s.parquet"
    t.to_parquet(q)
    pd.testing.assert_frame_equal(read_samples(q), got)
    ores = to_mineralogies(got)
    assert ores[1].name == "S2" and ores[1].fraction("kaolinite") == pytest.approx(0.30)


def test_every_bad_row_is_reported_with_id_column_value(tmp_path):
    t = _table()
    t["quartz_wt_pct"] = t["quartz_wt_pct"].astype(object)
    t.loc[1, "quartz_wt_pct"] = "abc"          # not a number
    t.loc[2, "uniformity"] = 1.5               # out of (0, 1]
    t.loc[0, "pyrite_wt_pct"] = 30.0           # sum 95
    t.loc[2, "sample_id"] = "S1"               # duplicate id
    p = tmp_path / "bad.csv"
    t.to_csv(p, index=False)
    with pytest.raises(SampleTableError) as err:
        read_samples(p)
    probs = {(pr.sample_id, pr.column): pr for pr in err.value.problems}
    assert probs[("S2", "quartz_wt_pct")].value == "abc"
    assert probs[("S1", "uniformity")].value == 1.5 and probs[("S1", "uniformity")].line == 3
    assert probs[("S1", "sum of _wt_pct columns")].value == pytest.approx(95.0)
    assert ("S1", "sample_id") in probs
    assert len(err.value.problems) == 4          # nothing dropped, nothing invented
    msg = str(err.value)
    assert "bad.csv" in msg and "'S2'" in msg and "'abc'" in msg and "quartz_wt_pct" in msg


def test_unknown_mineral_column_and_missing_texture():
    t = _table().rename(columns={"pyrite_wt_pct": "pyrit_wt_pct"}).drop(columns="uniformity")
    with pytest.raises(SampleTableError) as err:
        validate_samples(t)
    msg = str(err.value)
    assert "pyrit_wt_pct" in msg and "'pyrite'" in msg and "uniformity" in msg


def test_missing_value_is_reported_not_dropped():
    t = _table()
    t.loc[0, "mean_grain_um"] = np.nan
    with pytest.raises(TwinInputError, match=r"row 1 \(sample_id='S1'\): column 'mean_grain_um'"):
        validate_samples(t)


def test_library_honours_mission_table1_and_deposit_ranges():
    df = generate_library(seed=123)
    assert len(df) == 47 and df.sample_id.is_unique
    assert df.generating_type.value_counts().to_dict() == COUNTS
    clay = df.kaolinite_wt_pct + df.illite_wt_pct
    sulf = df.pyrite_wt_pct + df.chalcopyrite_wt_pct
    tol = 0.02  # rounding to 0.01 wt%
    for t, r in TABLE1_RANGES.items():
        sel = df.generating_type == t
        for key, values in (("quartz", df.quartz_wt_pct), ("clay", clay), ("sulfide", sulf),
                            ("grain_um", df.mean_grain_um)):
            lo, hi = r[key]
            assert values[sel].between(lo - tol, hi + tol).all(), (t, key)
    for key, values in (("quartz", df.quartz_wt_pct), ("clay", clay), ("sulfide", sulf)):
        lo, hi = DEPOSIT_RANGES[key]
        assert values.between(lo - tol, hi + tol).all(), key
    wt = df[[c for c in df.columns if c.endswith("_wt_pct")]].sum(axis=1)
    assert np.allclose(wt, 100.0, atol=1e-6)


def test_library_is_seeded_and_shipped_file_is_regenerable(tmp_path):
    a, b = generate_library(seed=5), generate_library(seed=5)
    pd.testing.assert_frame_equal(a, b)
    assert not generate_library(seed=6).equals(a)
    out = tmp_path / "lib.csv"
    assert main(["--out", str(out), "--seed", "47"]) == 0
    shipped = load_reference_samples()
    pd.testing.assert_frame_equal(read_samples(out), shipped)
    head = " ".join(read_header_comments(out))
    assert "SYNTHETIC" in head and "--seed 47" in head


def test_library_rejects_unknown_type():
    with pytest.raises(TwinInputError, match="counts"):
        generate_library(counts={"E": 3})
