"""Where a state of the twin lies outside what its models describe, one note each (empty when
inside): a hold-up beyond the mill filled to its shell (:meth:`twin.Mill.max_holdup_t`: the mill
would overflow), a speed where the charge centrifuges (:func:`twin.mill.centrifuging_note`) and,
with the rheology effect, a slurry past jamming (:func:`twin.effects.rheology.jamming_note`).
Every steady state carries them (:attr:`twin.solve.SteadyState.notes`); a run states them over
its samples (``scenarios.run.runner``)."""

from __future__ import annotations

from numbers import Real

from .mill import centrifuging_note


def overflow_note(holdup_t: float, capacity_t: float) -> str | None:
    """A note when a hold-up [t] exceeds the mill's shell capacity [t], else None."""
    if not holdup_t > capacity_t:
        return None
    return (f"hold-up {holdup_t:.4g} t is more than the mill holds filled to its shell ({capacity_t:.4g} t): "
            "it would overflow; these numbers extrapolate the model beyond the mill")


def state_notes(spec, effect_names, speed_frac_critical: float, holdup_t: float,
                clay_frac: float | None = None) -> list[str]:
    """The notes of a state of a model built from ``spec`` (:class:`twin.model.ModelSpec`) with
    ``effect_names``, at a speed [fraction of critical], hold-up [t] and hold-up clay fraction."""
    notes = [overflow_note(holdup_t, spec.mill.max_holdup_t(spec.solids_density_t_m3)),
             centrifuging_note(speed_frac_critical)]
    k_clay = spec.coefficients.get("clay_crowding_coeff")
    # a parametric model (twin.calibration.parametric) holds a symbol there: no number to compare
    if "rheology" in effect_names and clay_frac is not None and isinstance(k_clay, Real):
        from .effects.rheology import jamming_note

        notes.append(jamming_note(clay_frac, k_clay))
    return [n for n in notes if n]
