"""Data quality: status severity from the code's top bits, stale and future timestamps,
frozen values, Uncertain accepted only where the map says so."""

import math
from datetime import datetime, timedelta, timezone

import pytest
from asyncua import ua

from scenarios.online import Clock, Reading, TagQuality, severity

T0 = datetime(2030, 1, 1, tzinfo=timezone.utc)
CLOCK = Clock(speedup=60.0)  # a wall minute is a plant hour


def at(minutes):
    return T0 + timedelta(minutes=minutes)


@pytest.mark.parametrize("name, expected", [("Good", "good"), ("GoodLocalOverride", "good"),
                                            ("UncertainLastUsableValue", "uncertain"),
                                            ("UncertainSensorNotAccurate", "uncertain"),
                                            ("BadSensorFailure", "bad"), ("BadCommunicationError", "bad"),
                                            ("BadWaitingForInitialData", "bad")])
def test_severity_agrees_with_asyncua(name, expected):
    code = getattr(ua.StatusCodes, name)
    assert severity(code) == expected
    sc = ua.StatusCode(code)
    assert (sc.is_good(), sc.is_uncertain(), sc.is_bad()) == (expected == "good", expected == "uncertain",
                                                                expected == "bad")


def test_stale_after_max_age_in_plant_hours():
    q = TagQuality("p80", max_age_h=0.15)
    assert q.assess(Reading(210.0, 0, at(0)), at(0.1), CLOCK).ok  # 0.1 plant h old
    v = q.assess(Reading(210.0, 0, at(0)), at(0.2), CLOCK)
    assert (v.quality, v.ok) == ("stale", False) and "0.2 h old, limit 0.15 h" in v.reason
    v = q.assess(Reading(210.0, 0, at(0.5)), at(0.2), CLOCK)
    assert v.quality == "stale" and "future" in v.reason


def test_frozen_when_the_value_stays_while_timestamps_move():
    q = TagQuality("p80", max_age_h=1.0, frozen_after_h=0.2)
    verdicts = [q.assess(Reading(212.5, 0, at(m)), at(m), CLOCK) for m in (0, 0.1, 0.2, 0.3)]
    assert [v.quality for v in verdicts] == ["good", "good", "good", "frozen"]
    assert q.assess(Reading(212.6, 0, at(0.35)), at(0.35), CLOCK).quality == "good"  # moves again


def test_freeze_tolerance_and_no_check_without_a_limit():
    q = TagQuality("p", max_age_h=None, frozen_after_h=0.1, freeze_tolerance=0.5)
    assert q.assess(Reading(1.0, 0, at(0)), at(0), CLOCK).ok
    assert q.assess(Reading(1.4, 0, at(0.2)), at(0.2), CLOCK).quality == "frozen"
    free = TagQuality("feed", max_age_h=None)
    assert all(free.assess(Reading(20.0, 0, at(m)), at(m), CLOCK).ok for m in range(10))


def test_uncertain_rejected_unless_accepted_and_bad_always():
    unc = ua.StatusCodes.UncertainLastUsableValue
    assert TagQuality("a", None).assess(Reading(1.0, unc, at(0)), at(0), CLOCK).quality == "uncertain"
    v = TagQuality("a", None, accept_uncertain=True).assess(Reading(1.0, unc, at(0)), at(0), CLOCK)
    assert v.ok and v.value == 1.0
    v = TagQuality("a", None, accept_uncertain=True).assess(
        Reading(1.0, ua.StatusCodes.BadSensorFailure, at(0), status_name="BadSensorFailure"), at(0), CLOCK)
    assert not v.ok and math.isnan(v.value) and "BadSensorFailure" in v.reason


def test_not_a_number_is_bad_and_new_follows_the_timestamp():
    q = TagQuality("a", None)
    assert q.assess(Reading("abc", 0, at(0)), at(0), CLOCK).quality == "bad"
    assert q.assess(Reading(float("nan"), 0, at(0)), at(0), CLOCK).quality == "bad"
    assert q.assess(Reading(True, 0, at(0)), at(0), CLOCK).quality == "bad"
    assert q.assess(Reading(2.0, 0, at(1)), at(1), CLOCK).new
    assert not q.assess(Reading(2.0, 0, at(1)), at(1.5), CLOCK).new


def test_a_saturated_hardness_estimate_is_logged_when_it_starts_and_ends(caplog):
    """Service._estimate: the EKF's hardness at a bound of its range is a logged condition (once
    at its start, once at its end), as an unreadable tag is."""
    import logging
    from types import SimpleNamespace

    import numpy as np

    from scenarios.online.service import Service

    class Ekf:
        has_hardness, hardness_bounds, hardness_est = True, (0.3, 3.0), 1.0
        x_est = np.zeros(2)

        def make_step(self, y, u, d):
            return self.x_est, np.r_[d, self.hardness_est]

    svc = Service.__new__(Service)
    svc.parts, svc.bad_since, svc.est_start_h, svc.blend_prev = SimpleNamespace(estimator=Ekf()), {}, 0.0, [1.0]
    v = {"p80_um": SimpleNamespace(ok=True, new=True, value=200.0)}
    with caplog.at_level(logging.INFO, logger="grindtwin.online"):
        for t_h, h in ((0.1, 1.0), (0.2, 3.0), (0.3, 3.0), (0.4, 2.0)):
            svc.parts.estimator.hardness_est = h
            assert svc._estimate(v, [30.0, 0.7], [1.0], 1, t_h)[2] == ""
    text = [r.getMessage() for r in caplog.records]
    assert sum("hardness sits at a bound" in m for m in text) == 1 and "0.200 h" in text[0]
    assert any(m.startswith("0.400 h: hardness_bound good again after 0.200 h") for m in text)


def test_a_reading_outside_its_plausible_range_is_bad_with_tag_value_and_range():
    from scenarios.online.quality import PlausibleRange

    p80 = PlausibleRange(0.0, 6700.0, low_open=True, high_open=True, unit="um")
    q = TagQuality("p80_um", max_age_h=1.0, frozen_after_h=0.2, plausible=p80)
    v = q.assess(Reading(-5.0, 0, at(0)), at(0), CLOCK)
    assert (v.quality, v.ok) == ("bad", False) and math.isnan(v.value)
    assert v.reason == "p80_um = -5 is outside its plausible range (0, 6700) um"
    assert q.assess(Reading(1e6, 0, at(0.1)), at(0.1), CLOCK).quality == "bad"
    assert q.assess(Reading(0.0, 0, at(0.15)), at(0.15), CLOCK).quality == "bad"  # open end: a dead analyser's 0
    v = q.assess(Reading(212.5, 0, at(0.2)), at(0.2), CLOCK)
    assert (v.quality, v.value) == ("good", 212.5)
    # an accepted Uncertain reading is range-checked too
    unc = TagQuality("speed_frac_critical", None, accept_uncertain=True,
                     plausible=PlausibleRange(0.0, 1.0, True, True, "of critical"))
    v = unc.assess(Reading(3.0, ua.StatusCodes.UncertainLastUsableValue, at(0)), at(0), CLOCK)
    assert v.quality == "bad"
    assert v.reason == "speed_frac_critical = 3 is outside its plausible range (0, 1) of critical"


def test_closed_ends_include_their_limit_and_an_open_top_reads_as_such():
    from scenarios.online.quality import PlausibleRange

    power = PlausibleRange(0.0, unit="kW")
    assert 0.0 in power and 1e5 in power and -1e-9 not in power
    assert str(power) == "[0, inf) kW"
    span = PlausibleRange(20.0, 45.0)
    assert 20.0 in span and 45.0 in span and 45.001 not in span and str(span) == "[20, 45]"


def test_a_power_reading_in_mw_is_bad_while_the_mill_turns():
    """0.163 for 163 kW (MW read as kW) lay inside the physical range, which starts at a stopped mill's 0, and was
    Good: while the actual speed says the mill turns, a power under a tenth of the model's at that speed is Bad,
    naming the reading, the speed and the model's power; a stopped mill's 0 and a usable kW reading stay Good."""
    from types import SimpleNamespace

    from scenarios.online.quality import Verdict
    from scenarios.online.service import POWER_TURNING_MIN_FRAC, Service
    from twin import get_mill, power_kw

    mill = get_mill("industrial")
    svc = Service.__new__(Service)
    svc.parts = SimpleNamespace(models=SimpleNamespace(control=SimpleNamespace(mill=mill)))
    model_kw = float(power_kw(mill, 0.7))

    def judged(power, speed):
        return svc._power_while_turning({"power_kw": Verdict(power, "good"), "speed_frac_critical": Verdict(speed,
                                                                                                          "good")})
    bad = judged(model_kw / 1000.0, 0.7)["power_kw"]
    assert not bad.ok and bad.quality == "bad" and "MW? kW expected" in bad.reason and f"{model_kw:.4g} kW" in bad.reason
    assert judged(1.01 * POWER_TURNING_MIN_FRAC * model_kw, 0.7)["power_kw"].ok
    assert not judged(0.99 * POWER_TURNING_MIN_FRAC * model_kw, 0.7)["power_kw"].ok
    assert judged(0.0, 0.0)["power_kw"].ok and judged(model_kw, 0.7)["power_kw"].ok


def test_a_feed_reading_in_other_units_is_bad_while_the_service_writes_the_feed():
    """8.33 for 30 t/h (a feed in kg/s) lay inside the physical range, which starts at a stopped feeder's 0, and was
    Good: the estimator ran on a third of the feed. While the service is in auto, a feed reading beyond a factor of
    the setpoint it wrote is Bad, naming both; a reading near it, a stopped feeder's 0 and readings in manual (the
    operator's setpoint, not the service's) stay Good."""
    import numpy as np

    from scenarios.online.quality import Verdict
    from scenarios.online.service import FEED_FOLLOW_FACTOR, Service

    svc = Service.__new__(Service)
    svc.mode, svc.u_written = "auto", np.array([30.0, 0.7])

    def judged(feed):
        return svc._feed_following({"feed_tph": Verdict(feed, "good"), "speed_frac_critical": Verdict(0.7, "good")})

    for slip in (30.0 / 3.6, 30.0 / 60.0, 30.0e3):  # kg/s, t/min, kg/h
        bad = judged(slip)["feed_tph"]
        assert not bad.ok and bad.quality == "bad" and "kg/s? kg/h?" in bad.reason and "setpoint is 30 t/h" in bad.reason
    assert judged(1.01 * 30.0 / FEED_FOLLOW_FACTOR)["feed_tph"].ok and judged(0.99 * 30.0 * FEED_FOLLOW_FACTOR)[
        "feed_tph"].ok
    assert not judged(0.99 * 30.0 / FEED_FOLLOW_FACTOR)["feed_tph"].ok
    assert judged(0.0)["feed_tph"].ok and judged(29.0)["feed_tph"].ok
    svc.mode = "manual"
    assert judged(30.0 / 3.6)["feed_tph"].ok


def test_a_held_value_stamped_anew_is_not_a_new_report_before_its_sources_period():
    """A gateway stamping the held P80 anew every scan made each cycle (0.05 h) take it as a new analysis of an
    analyser reporting every 0.15 h: the estimator updated on it three times as often."""
    q = TagQuality("p80", max_age_h=0.3, report_period_h=0.15)
    news = [q.assess(Reading(210.0, 0, at(t)), at(t), CLOCK).new for t in (0.0, 0.05, 0.1, 0.15, 0.2)]
    assert news == [True, False, False, True, False]  # the same number once a period: an analyser may repeat it
    assert q.assess(Reading(212.0, 0, at(0.25)), at(0.25), CLOCK).new  # a changed value is a new report at once
    assert not q.assess(Reading(212.0, 0, at(0.25)), at(0.3), CLOCK).new  # the timestamp did not move
    every = TagQuality("p80", max_age_h=0.3)  # no period given: each moved timestamp, as before
    assert all(every.assess(Reading(210.0, 0, at(t)), at(t), CLOCK).new for t in (0.0, 0.05, 0.1))


def test_the_service_judges_new_reports_on_each_sources_period(small_scene, small_tags, small_parts, tmp_path):
    from scenarios.online.tags import source_period_h

    import scenarios.online as online
    service = online.Service(small_parts, small_tags, online.ServeSettings(
        "opc.tcp://127.0.0.1:4840", online.ClientSecurity(insecure=True), tmp_path / "audit"))
    assert service.quality["p80_um"].report_period_h == source_period_h("p80_um", small_scene)
    assert service.quality["blend.B"].report_period_h == source_period_h("belt_analyser", small_scene)
