"""The PCA + PLS surrogate (eq. 8): accuracy on unseen mineralogies, agreement with the twin,
refusal outside the training domain, persistence."""

import joblib
import numpy as np
import pytest

from twin import surrogate as S
from twin.errors import TwinError, TwinInputError
from twin.ore.mineralogy import WT_SUFFIX, Mineralogy, Texture
from twin.ore.ores import Blend, reference_ores
from twin.ore.sample_library import generate_library
from twin.ore.samples import to_mineralogies
from twin.twin import Twin

#: Acceptance threshold of R2 per KPI on unseen mineralogies. MISSION's goal is 0.95; P80 and
#: energy reach ~0.999, so 0.99 catches their degradation long before the goal is missed. The
#: load is held to MISSION's goal itself: since the table step made the lab grate a sharp cut
#: (sharpness ~8, with the clay crowding bounded below jamming) the hold-up climbs steeply
#: toward overload for hard ores at high feed, which a quadratic PLS in log space follows less
#: well (README, Limitations: it was held to 0.99 on the soft grate before).
R2_THRESHOLD = {"p80_um": 0.99, "specific_energy_kwh_t": 0.99, "load_frac": 0.95}
#: Agreement with the twin on fresh points: worst relative error per KPI. P80's is the widest on
#: the DEM calibration (its mapped rates vary more across mineralogies than the table map's did;
#: benchmarks/results/twin_surrogate.md has the held-out errors); the load's, on the sharp grate
#: (above), is as wide as P80's.
REL_TOL = {"p80_um": 0.08, "specific_energy_kwh_t": 0.03, "load_frac": 0.08}


@pytest.fixture(scope="module")
def table():
    return S.load_training_table()


@pytest.fixture(scope="module")
def split_fit(table):
    train, test = S.held_out_split(table)
    X, Y, _ = S.split_xy(train)
    return S.Surrogate(**S.DEFAULT_PARAMS).fit(X, Y), test


@pytest.fixture(scope="module")
def shipped():
    return S.shipped_surrogate()


def test_held_out_r2_meets_threshold(split_fit):
    sur, test = split_fit
    X, Y, g = S.split_xy(test)
    assert len(np.unique(g)) >= 60  # 20 % of 320 mineralogies, none seen in training
    r2 = sur.r2_per_kpi(X, Y)
    for kpi, v in r2.items():
        assert v >= R2_THRESHOLD[kpi], f"{kpi}: R2 {v:.4f} on unseen mineralogies < {R2_THRESHOLD[kpi]}"


def test_r2_test_can_fail(table):
    """A one-component linear PLS misses the threshold on the same split: the test discriminates."""
    train, test = S.held_out_split(table)
    weak = S.Surrogate(n_components=1, n_pca=2, degree=1).fit(*S.split_xy(train)[:2])
    assert any(v < R2_THRESHOLD[k] for k, v in weak.r2_per_kpi(*S.split_xy(test)[:2]).items())


def test_shipped_metadata_and_scores(shipped):
    meta = shipped.metadata_
    assert meta["command"] == "python -m twin.surrogate --train"
    assert meta["table_command"] == "python -m twin.surrogate --generate"
    assert meta["design"]["seed"] == S.DEFAULT_SEED and meta["mill"] == "lab"
    assert meta["failed_steady_states"] == 0
    for kpi in S.TARGETS:
        assert meta["cv_r2"][kpi] >= R2_THRESHOLD[kpi] and meta["held_out_r2"][kpi] >= R2_THRESHOLD[kpi]
    assert meta["calibration"]["name"] == "dem" and meta["calibration_sha256"] == S.calibration_sha256(), (
        "twin/calibration/files/dem.json (the default calibration) changed since the surrogate was trained: "
        "regenerate with `python -m twin.surrogate --generate --train`")


def test_refuses_a_calibration_it_was_not_trained_on(shipped):
    from twin.calibration import load_calibration

    S.check_trained_on(shipped, load_calibration("dem"))
    with pytest.raises(TwinInputError, match="another calibration than 'table'.*on 'dem'.*--calibration table"):
        S.surrogate_steady("B", surrogate=shipped, calibration="table")
    edited = load_calibration("dem").with_values(coefficients={"clay_crowding_coeff": 1.0})
    with pytest.raises(TwinInputError, match="another calibration"):
        S.check_trained_on(shipped, edited)  # a calibration in memory has no file hash


def test_compiled_predict_equals_pipeline(split_fit):
    sur, test = split_fit
    X = S.split_xy(test)[0]
    np.testing.assert_allclose(sur.predict(X, check_domain=False), sur.predict_pipeline(X), rtol=1e-12)


def test_agrees_with_twin_on_fresh_points(shipped):
    """Mineralogies never used in training (a fresh library seed, and a blend run by the twin
    component by component as `grindtwin steady --blend` does) at three operating points."""
    ores = to_mineralogies(generate_library(seed=31337, counts={"A": 1, "B": 1, "C": 1, "D": 1}))
    cases = [(o, Twin(o, mill="lab")) for o in ores]
    blend = Blend.parse("B=0.6,D=0.4")
    cases.append((blend, Twin(blend, mill="lab")))
    worst = {k: 0.0 for k in S.TARGETS}
    for ore, twin in cases:
        for feed, speed in ((0.022, 0.64), (0.031, 0.70), (0.044, 0.82)):
            ref = S.twin_kpis(twin, feed, speed)
            got = S.surrogate_steady(ore, feed, speed, surrogate=shipped)
            for k in S.TARGETS:
                worst[k] = max(worst[k], abs(got[k] / ref[k] - 1.0))
    for k, err in worst.items():
        assert err <= REL_TOL[k], f"{k}: worst relative error {err:.3%} > {REL_TOL[k]:.0%}"


@pytest.mark.parametrize("row", [0, 853, 1706, 2559])
def test_training_table_is_what_the_twin_computes_now(table, row):
    """The shipped table's steady states, rerun: a change of the twin's equations that leaves the
    calibration's table point alone (twin.calibration.model_code) still shows here, and the
    surrogate must be regenerated (python -m twin.surrogate --generate --train --compile)."""
    from twin.calibration.model_code import PREDICTION_RTOL

    r = table.iloc[row]
    wt = {c[:-len(WT_SUFFIX)]: float(r[c]) for c in table.columns if c.endswith(WT_SUFFIX) and r[c] > 0}
    ore = Mineralogy(wt, Texture(float(r.mean_grain_um), float(r.uniformity), float(r.association_entropy)))
    got = S.twin_kpis(Twin(ore, mill=table.attrs["mill"]), float(r.feed_tph), float(r.speed_frac_critical))
    for k in S.TARGETS:
        assert got[k] == pytest.approx(r[k], rel=PREDICTION_RTOL), k


@pytest.mark.parametrize("args, field", [
    (("B", 0.10, 0.70), "'feed_tph'"),
    (("B", 0.031, 0.90), "'speed_frac_critical'"),
    ((Mineralogy({"quartz": 40, "k_feldspar": 12, "plagioclase": 6, "biotite": 18, "chlorite": 2, "kaolinite": 4,
                  "illite": 3, "pyrite": 10, "chalcopyrite": 0.5, "bornite": 4.5}, Texture(125, 0.6, 0.55)),
      0.031, 0.70), "'bornite_wt_pct'"),
    ((Mineralogy({"quartz": 60, "kaolinite": 30, "biotite": 10}, Texture(100.0)), 0.031, 0.70), "PCA"),
    ((Mineralogy(reference_ores()["B"].wt_pct, Texture(2000.0, 0.6, 0.55)), 0.031, 0.70), "'mean_grain_um'"),
])
def test_out_of_domain_refused(shipped, args, field):
    with pytest.raises(TwinInputError, match="training domain") as exc:
        S.surrogate_steady(*args, surrogate=shipped)
    msg = str(exc.value)
    assert field in msg


def test_refusal_message_names_value_and_range(shipped):
    with pytest.raises(TwinInputError) as exc:
        S.surrogate_steady("B", 0.10, 0.70, surrogate=shipped)
    lo, hi = shipped.input_range_["feed_tph"]
    assert f"[{lo:.6g}, {hi:.6g}]. Got 0.1." in str(exc.value)


def test_inside_domain_accepted_for_reference_ores_and_cli_blend(shipped):
    for ore in ("A", "B", "C", "D", Blend.parse("B=0.6,D=0.4"), Blend.parse("A=0.8,C=0.2")):
        for feed, speed in ((0.0155, 0.605), (0.031, 0.70), (0.049, 0.845)):
            S.surrogate_steady(ore, feed, speed, surrogate=shipped)


def test_surrogate_steady_keys(shipped):
    out = S.surrogate_steady("B", 0.031, 0.70, surrogate=shipped)
    assert out["source"] == "surrogate"
    assert out["throughput_tph"] == out["feed_tph"] == 0.031
    assert out["power_kw"] == pytest.approx(out["specific_energy_kwh_t"] * 0.031)
    assert out["load_status"] == "stable" and 180 < out["p80_um"] < 260
    assert {"p80_um", "specific_energy_kwh_t", "load_frac", "holdup_t", "soft_frac", "speed_frac_critical"} <= set(out)
    with pytest.raises(TwinInputError, match="'mill'"):
        S.surrogate_steady("B", 30.0, 0.70, mill="industrial", surrogate=shipped)


def test_save_load_round_trip(split_fit, tmp_path):
    sur, test = split_fit
    X = S.split_xy(test)[0]
    path = S.save(sur, tmp_path / "s.joblib", {"mill": "lab"})
    back = S.load(path)
    assert np.array_equal(back.predict(X, check_domain=False), sur.predict(X, check_domain=False))
    assert back.get_params() == sur.get_params() and back.metadata_["mill"] == "lab"


@pytest.mark.parametrize("key, value", [("format_version", 999), ("sklearn", "0.1.0")])
def test_load_refuses_other_versions(split_fit, tmp_path, key, value):
    path = S.save(split_fit[0], tmp_path / "s.joblib")
    blob = joblib.load(path)
    blob["metadata"][key] = value
    joblib.dump(blob, path)
    with pytest.raises(TwinError, match="Regenerate"):
        S.load(path)


@pytest.mark.parametrize("params", [{"degree": 3}, {"n_pca": 0}, {"n_components": 10_000}])
def test_bad_parameters_refused(table, params):
    X, Y, _ = S.split_xy(table.iloc[:200])
    with pytest.raises(TwinInputError, match="parameter of Surrogate"):
        S.Surrogate(**params).fit(X, Y)


def test_unfitted_and_bad_input():
    with pytest.raises(TwinError, match="not fitted"):
        S.Surrogate().predict(S.feature_frame("B", 0.031, 0.7))
    with pytest.raises(TwinInputError, match="DataFrame"):
        S.Surrogate().fit([[1, 2]], [[1, 2, 3]])


def test_design_is_seeded_and_in_range():
    a = S.design_mineralogies(seed=5, n_mineralogies=16)
    b = S.design_mineralogies(seed=5, n_mineralogies=16)
    assert [m.wt_pct for m, _ in a] == [m.wt_pct for m, _ in b]
    kinds = [k.split(":")[0] for _, k in a]
    assert kinds.count("library") == 8 and kinds.count("library-mix") == 4 and kinds.count("reference") == 4
    pts = S.design_conditions(64, np.random.default_rng(0))
    assert pts[:, 0].min() >= S.FEED_RANGE_TPH[0] and pts[:, 0].max() <= S.FEED_RANGE_TPH[1]
    assert pts[:, 1].min() >= S.SPEED_RANGE[0] and pts[:, 1].max() <= S.SPEED_RANGE[1]
    # Latin hypercube: one point per stratum of log-feed and of speed
    lf = (np.log(pts[:, 0]) - np.log(S.FEED_RANGE_TPH[0])) / np.log(S.FEED_RANGE_TPH[1] / S.FEED_RANGE_TPH[0])
    assert sorted(np.floor(lf * 64).astype(int)) == list(range(64))


def test_table_generation_small(tmp_path):
    """The generator end to end on a tiny design: columns, no failures, provenance."""
    t = S.generate_training_table(seed=3, n_mineralogies=8, points_per_mineralogy=2)
    assert len(t) == 16 and set(S.TARGETS) <= set(t.columns) and t.attrs["failed"] == []
    assert t.attrs["command"] == S.GENERATE_COMMAND and t.attrs["calibration_sha256"] == S.calibration_sha256()
    t.to_parquet(tmp_path / "t.parquet")
    assert S.load_training_table(tmp_path / "t.parquet").attrs["seed"] == 3


def test_surrogate_steady_defaults_and_bad_numbers(shipped):
    out = S.surrogate_steady("B", surrogate=shipped)  # the lab mill's nominal 0.031 t/h, 0.70
    assert (out["feed_tph"], out["speed_frac_critical"]) == (0.031, 0.70)
    for bad in ("fast", float("nan")):
        with pytest.raises(TwinInputError, match="'feed_tph' parameter of surrogate_steady"):
            S.surrogate_steady("B", bad, 0.70, surrogate=shipped)
