"""The soft sensor: the twin's steady state of the incoming blend at the actual inputs, Good
inside the surrogate's training domain and Uncertain outside; the surrogate's answer on its own
mill, Bad outside its domain; and what the served drill published."""

import pytest
from asyncua import ua

import scenarios.online as online
from scenarios.errors import SceneError
from twin import Mineralogy, Texture, Twin, reference_ores
from twin.surrogate import blend_mineralogy, surrogate_steady
from twin import Blend

#: Far outside the deposit the surrogate was trained on (pyrite 2-18 % there).
PYRITIC = Mineralogy({"quartz": 20.0, "pyrite": 70.0, "kaolinite": 10.0}, Texture(100.0, 0.5, 0.5), name="P")


def _ore(name):
    ref = reference_ores()[name]
    return Mineralogy(dict(ref.wt_pct), ref.texture, name=name)


@pytest.fixture(scope="module")
def lab():
    ores = {"B": _ore("B"), "D": _ore("D")}
    twin = Twin(list(ores.values()), mill="lab")
    return twin, online.SoftSensor(twin, ores, "lab", with_surrogate=True)


def test_inside_the_domain_both_answers_are_good_and_agree(lab):
    twin, soft = lab
    p = soft.predict([0.6, 0.4], 0.031, 0.70)
    ss = twin.steady(feed_tph=0.031, speed_frac_critical=0.70, blend=[0.6, 0.4])
    assert (p.p80_um, p.specific_energy_kwh_t) == (ss.p80_um, ss.outputs["specific_energy_kwh_t"])
    ref = surrogate_steady(blend_mineralogy(Blend((_ore("B"), _ore("D")), (0.6, 0.4))), 0.031, 0.70)
    assert p.surrogate_p80_um == ref["p80_um"]
    assert (p.status, p.surrogate_status) == (ua.StatusCodes.Good, ua.StatusCodes.Good)
    assert abs(p.surrogate_p80_um / p.p80_um - 1) < 0.08  # the surrogate learnt this twin (its test's P80 tolerance)


def test_at_zero_feed_the_twins_answer_is_bad_not_a_number_called_good(lab):
    _, soft = lab
    p = soft.predict([0.6, 0.4], 0.0, 0.70)  # no product: no P80, no energy per tonne fed
    assert p.status == ua.StatusCodes.BadInternalError and "no product" in p.reason


def test_outside_the_domain_the_twin_is_uncertain_and_the_surrogate_bad():
    ores = {"B": _ore("B"), "P": PYRITIC}
    soft = online.SoftSensor(Twin(list(ores.values()), mill="lab"), ores, "lab", with_surrogate=True)
    p = soft.predict([0.5, 0.5], 0.031, 0.70)
    assert p.status == ua.StatusCodes.UncertainEngineeringUnitsExceeded and p.p80_um > 0
    assert "pyrite_wt_pct" in p.reason
    assert p.surrogate_status == ua.StatusCodes.BadOutOfRange and p.surrogate_p80_um is None
    assert soft.predict([1.0, 0.0], 0.031, 0.70).status == ua.StatusCodes.Good  # pure B: inside


def test_on_another_mill_the_domain_is_judged_on_the_mineralogy(small_parts):
    soft = small_parts.soft_sensor  # industrial mill: 16 t/h is far beyond the lab's feed range
    assert soft.predict([0.6, 0.4], 16.0, 0.70).status == ua.StatusCodes.Good
    ores = {"B": _ore("B"), "P": PYRITIC}
    with pytest.raises(SceneError, match="trained for the 'lab' mill; the scene's mill is 'industrial'"):
        online.SoftSensor(small_parts.models.control, ores, "industrial", with_surrogate=True)
