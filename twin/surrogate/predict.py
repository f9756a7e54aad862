"""One steady-state answer from the surrogate, with the keys of the ``steady`` command's JSON."""

from __future__ import annotations

import math

import numpy as np

from ..calibration import load_calibration
from ..errors import TwinInputError, bad_value
from ..mill import get_mill, load_status
from ..ore import CUSHIONING_MINERALS
from ..ore.samples import TEXTURE_COLUMNS
from .files import check_trained_on, shipped_surrogate
from .inputs import as_mineralogy, mineral_names
from .model import Surrogate


def _number(field: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise bad_value("surrogate_steady", field, value, "a finite float") from None
    if not math.isfinite(v):
        raise bad_value("surrogate_steady", field, value, "a finite float")
    return v


def surrogate_steady(mineralogy, feed_tph: float | None = None, speed_frac_critical: float | None = None,
                     mill: str = "lab", surrogate: Surrogate | None = None, calibration=None) -> dict:
    """Steady-state KPIs from the surrogate, keys as the ``steady`` command's JSON.

    ``mineralogy``: a Mineralogy, a Blend (taken as its mass-weighted mineralogy), a
    reference type letter or an ore TOML path. ``feed_tph`` and ``speed_frac_critical``
    default to the mill's nominal values (as :meth:`Twin.steady`). Raises TwinInputError
    outside the training domain (field, value, trained range), for a mill the surrogate was
    not trained for, or for a calibration (default: the default one) it was not trained on.
    """
    sur = surrogate or shipped_surrogate()
    cal = load_calibration(calibration)
    check_trained_on(sur, cal)
    trained_mill = getattr(sur, "metadata_", {}).get("mill", "lab")
    if mill != trained_mill:
        raise TwinInputError(f"The 'mill' of surrogate_steady must be {trained_mill!r} (the mill the surrogate "
                             f"was trained for). Got {mill!r}.")
    ore = as_mineralogy(mineralogy)
    m = get_mill(mill, cal.record)
    feed = _number("feed_tph", m.feed_nominal_tph if feed_tph is None else feed_tph)
    speed = _number("speed_frac_critical", m.speed_nominal_frac_critical if speed_frac_critical is None
                    else speed_frac_critical)
    row = [ore.wt_pct.get(k, 0.0) for k in mineral_names()] + [float(getattr(ore.texture, c)) for c in TEXTURE_COLUMNS]
    row += [feed, speed]  # the order of input_columns / feature_names_in_
    sur._check_fitted()
    p80, se, load = sur._predict_array(np.array([row], float))[0]
    return {"source": "surrogate", "mill": mill, "feed_tph": feed, "speed_frac_critical": speed,
            "p80_um": float(p80), "specific_energy_kwh_t": float(se), "power_kw": float(se * feed),
            "throughput_tph": feed, "discharge_tph": feed, "load_frac": float(load),
            "holdup_t": float(load * m.nominal_holdup_t(ore.density_t_m3)),
            "soft_frac": ore.group_fraction(CUSHIONING_MINERALS),
            "load_status": load_status(float(load), m.stable_band)}
