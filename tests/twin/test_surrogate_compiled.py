"""The shipped surrogate's compiled form (surrogate.json): the shipped joblib's own arrays, made
from the shipped calibration, predicting exactly what the estimator predicts; refused when stale."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.surrogate as S
from twin.errors import TwinError, TwinInputError
from twin.surrogate import files
from twin import file_sha256
from twin.surrogate.compiled import CompiledSurrogate


def test_shipped_npz_is_the_shipped_joblib_compiled_on_the_shipped_calibration():
    meta = S.shipped_compiled().metadata
    assert meta["joblib_sha256"] == file_sha256(S.MODEL_PATH), f"stale: run `{S.COMPILE_COMMAND}`"
    assert meta["calibration_sha256"] == S.calibration_sha256()


def test_compiled_file_predicts_what_the_estimator_predicts():
    table = S.load_training_table()
    X, _, _ = S.split_xy(table.iloc[::7])
    A = X.to_numpy(float)
    sur = S.shipped_surrogate()
    np.testing.assert_array_equal(S.shipped_compiled().predict(A), sur.predict(X))
    np.testing.assert_allclose(S.shipped_compiled().predict(A), sur.predict_pipeline(X), rtol=1e-9)
    assert S.surrogate_steady("B", 0.031, 0.70) == S.surrogate_steady("B", 0.031, 0.70, surrogate=sur)


def test_compiled_form_refuses_what_the_estimator_refuses():
    with pytest.raises(TwinInputError, match="'feed_tph' input of Surrogate must be in the trained range"):
        S.surrogate_steady("B", 0.10, 0.70)


def test_a_compiled_file_from_another_calibration_is_refused(tmp_path, monkeypatch):
    stale = S.shipped_compiled()
    path = CompiledSurrogate(stale.feature_names, stale.arrays, stale.score_range, stale.q_limit,
                             dict(stale.metadata, calibration_sha256="0" * 64)).save(tmp_path / "s.json")
    monkeypatch.setattr(files, "COMPILED_PATH", path)
    with pytest.raises(TwinError, match="another calibration"):
        files.shipped_compiled.__wrapped__()
    round_trip = CompiledSurrogate.load(path)
    assert round_trip.feature_names == stale.feature_names and round_trip.q_limit == stale.q_limit


def test_an_unchecked_row_outside_the_domain_predicts_nan_not_a_number():
    """Without the domain check, a non-positive log input gives NaN KPIs (as numpy's exp of NaN),
    never a finite value or an infinity that could pass for one."""
    sur = S.shipped_compiled()
    row = list(S.load_training_table()[list(sur.feature_names)].iloc[0])
    row[sur.feature_names.index("feed_tph")] = -1.0
    out = sur.predict([row], check_domain=False)[0]
    assert all(math.isnan(v) for v in out), out
    with pytest.raises(TwinInputError, match="feed_tph"):
        sur.predict([row])


def test_a_table_is_read_by_column_name_not_position():
    sur = S.shipped_compiled()
    table = S.load_training_table()[list(sur.feature_names)].iloc[:3]
    shuffled = table[list(reversed(table.columns))]
    assert sur.predict(shuffled) == sur.predict(table.to_numpy(float))
    with pytest.raises(TwinInputError, match="lacks the columns"):
        sur.predict(table.drop(columns=["feed_tph"]))
