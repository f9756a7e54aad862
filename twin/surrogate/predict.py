"""One steady-state answer from the surrogate, with the keys of the ``steady`` command's JSON.

Plain Python: the shipped surrogate is read in its compiled form (:mod:`twin.surrogate.compiled`),
so ``grindtwin steady --surrogate`` imports neither numpy, scikit-learn nor CasADi."""

from __future__ import annotations

import math

from ..calibration.files import load_calibration
from ..errors import TwinInputError, bad_value
from ..mill import get_mill, load_status
from ..ore.mineralogy import TEXTURE_COLUMNS, WT_SUFFIX
from ..ore.minerals import CUSHIONING_MINERALS
from .files import check_trained_on, shipped_compiled
from .inputs import CONDITION_COLUMNS, as_mineralogy


def _number(field: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise bad_value("surrogate_steady", field, value, "a finite float") from None
    if not math.isfinite(v):
        raise bad_value("surrogate_steady", field, value, "a finite float")
    return v


def input_row(names, ore, feed_tph: float, speed_frac_critical: float) -> list[float]:
    """One input row in the order ``names`` (the surrogate's feature names): mineral wt%, texture,
    feed rate and speed."""
    conditions = dict(zip(CONDITION_COLUMNS, (feed_tph, speed_frac_critical)))
    row = []
    for name in names:
        if name.endswith(WT_SUFFIX):
            row.append(ore.wt_pct.get(name[: -len(WT_SUFFIX)], 0.0))
        elif name in TEXTURE_COLUMNS:
            row.append(float(getattr(ore.texture, name)))
        else:
            row.append(conditions[name])
    return row


def surrogate_steady(mineralogy, feed_tph: float | None = None, speed_frac_critical: float | None = None,
                     mill: str = "lab", surrogate=None, calibration=None) -> dict:
    """Steady-state KPIs from the surrogate, keys as the ``steady`` command's JSON.

    ``mineralogy``: a Mineralogy, a Blend (taken as its mass-weighted mineralogy), a
    reference type letter or an ore TOML path. ``feed_tph`` and ``speed_frac_critical``
    default to the mill's nominal values (as :meth:`Twin.steady`). Raises TwinInputError
    outside the training domain (field, value, trained range), for a mill the surrogate was
    not trained for, or for a calibration (default: the default one) it was not trained on.
    ``surrogate``: a fitted Surrogate or a CompiledSurrogate (default: the shipped one, compiled).
    """
    sur = shipped_compiled() if surrogate is None else surrogate
    sur = sur if hasattr(sur, "arrays") else sur.compiled()
    cal = load_calibration(calibration)
    check_trained_on(sur, cal)
    trained_mill = sur.metadata.get("mill", "lab")
    if mill != trained_mill:
        raise TwinInputError(f"The 'mill' of surrogate_steady must be {trained_mill!r} (the mill the surrogate "
                             f"was trained for). Got {mill!r}.")
    ore = as_mineralogy(mineralogy)
    m = get_mill(mill, cal.record)
    feed = _number("feed_tph", m.feed_nominal_tph if feed_tph is None else feed_tph)
    speed = _number("speed_frac_critical", m.speed_nominal_frac_critical if speed_frac_critical is None
                    else speed_frac_critical)
    p80, se, load = sur.predict([input_row(sur.feature_names, ore, feed, speed)])[0]
    return {"source": "surrogate", "mill": mill, "feed_tph": feed, "speed_frac_critical": speed,
            "p80_um": float(p80), "specific_energy_kwh_t": float(se), "power_kw": float(se * feed),
            "throughput_tph": feed, "discharge_tph": feed, "load_frac": float(load),
            "holdup_t": float(load * m.nominal_holdup_t(ore.density_t_m3)),
            "soft_frac": ore.group_fraction(CUSHIONING_MINERALS),
            "load_status": load_status(float(load), m.stable_band)}
