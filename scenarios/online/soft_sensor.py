"""The soft sensor online: predicted P80 and specific energy of the ore on the belt, at the
actual feed rate and speed, with the surrogate's training domain as the quality flag.

Two predictions of the steady state the incoming blend would reach:
- the twin's (the scene's twin, :meth:`twin.Twin.steady`): any mill. Good inside the
  surrogate's training domain (the mineralogies the calibration's design spans), Uncertain
  outside it (the twin extrapolates from its physics, not from data), Bad if the steady state fails;
- the PLS surrogate's (:func:`twin.surrogate.surrogate_steady`), on the mill it was trained for
  only: Good inside its domain, Bad outside (it refuses to extrapolate).
On another mill than the surrogate's, the domain is judged on the mineralogy alone (the
operating conditions are set to the trained mill's nominal ones).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from asyncua import ua

from scenarios.errors import SceneError
from twin import Blend, TwinError, get_mill
from twin.calibration import shipped_calibration
from twin.surrogate import blend_mineralogy, feature_frame, shipped_surrogate, surrogate_steady

GOOD = ua.StatusCodes.Good
#: The twin's value for a mineralogy outside the training domain: a value beyond the range it
#: was checked on (OPC 10000-4, 7.39: "UncertainEngineeringUnitsExceeded").
OUTSIDE_DOMAIN = ua.StatusCodes.UncertainEngineeringUnitsExceeded
#: The surrogate's answer outside its domain: none ("BadOutOfRange").
REFUSED = ua.StatusCodes.BadOutOfRange
FAILED = ua.StatusCodes.BadInternalError


@dataclass(frozen=True)
class SoftPrediction:
    """One prediction: values, OPC UA status codes and the reasons for a non-Good status."""

    p80_um: float
    specific_energy_kwh_t: float
    status: int
    reason: str
    surrogate_p80_um: float | None = None
    surrogate_specific_energy_kwh_t: float | None = None
    surrogate_status: int | None = None
    surrogate_reason: str = ""


class SoftSensor:
    """Predictions for blends of ``ores`` (name -> twin Mineralogy, in the twin's component
    order) on the scene's ``twin`` and mill preset; ``with_surrogate`` also answers from the surrogate."""

    def __init__(self, twin, ores: dict, mill_preset: str, with_surrogate: bool = False):
        self.twin, self.ores = twin, list(ores.values())
        self.surrogate = shipped_surrogate()
        self.trained_mill = self.surrogate.metadata_.get("mill", "lab")
        self.mill_preset = mill_preset
        if with_surrogate and mill_preset != self.trained_mill:
            raise SceneError(f"soft_sensor.surrogate_p80_um: the surrogate is trained for the "
                             f"{self.trained_mill!r} mill; the scene's mill is {mill_preset!r} "
                             "(publish the twin's prediction only)")
        self.with_surrogate = with_surrogate
        nominal = get_mill(self.trained_mill, shipped_calibration())
        self._nominal = (nominal.feed_nominal_tph, nominal.speed_nominal_frac_critical)

    def domain_problems(self, mineralogy, feed_tph: float, speed: float) -> list[str]:
        """Why the incoming ore lies outside the surrogate's training domain (empty: inside)."""
        cond = (feed_tph, speed) if self.mill_preset == self.trained_mill else self._nominal
        return self.surrogate.domain_problems(feature_frame(mineralogy, *cond), max_problems=3)

    def predict(self, blend, feed_tph: float, speed: float) -> SoftPrediction:
        fracs = [float(f) for f in blend]
        mineralogy = blend_mineralogy(Blend(tuple(self.ores), tuple(fracs)))
        problems = self.domain_problems(mineralogy, feed_tph, speed)
        try:
            ss = self.twin.steady(feed_tph=feed_tph, speed_frac_critical=speed, blend=fracs)
            p80, se = float(ss.p80_um), float(ss.outputs["specific_energy_kwh_t"])
            status = OUTSIDE_DOMAIN if problems else GOOD
            reason = "outside the training domain: " + " | ".join(problems) if problems else ""
            if not (math.isfinite(p80) and math.isfinite(se)):  # e.g. no feed: no product
                status, reason = FAILED, f"undefined at feed {feed_tph:g} t/h (no product)"
        except TwinError as exc:
            p80 = se = float("nan")
            status, reason = FAILED, f"the twin's steady state failed: {exc}"
        out = dict(p80_um=p80, specific_energy_kwh_t=se, status=status, reason=reason)
        if self.with_surrogate:
            try:
                k = surrogate_steady(mineralogy, feed_tph, speed, mill=self.mill_preset, surrogate=self.surrogate)
                out |= dict(surrogate_p80_um=k["p80_um"], surrogate_specific_energy_kwh_t=k["specific_energy_kwh_t"],
                            surrogate_status=GOOD)
            except TwinError as exc:
                out |= dict(surrogate_p80_um=None, surrogate_specific_energy_kwh_t=None, surrogate_status=REFUSED,
                            surrogate_reason=str(exc))
        return SoftPrediction(**out)
