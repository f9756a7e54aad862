"""Parametric twins: a twin built once with its calibration's numbers as CasADi symbols, so that
a table fit, a bootstrap replicate or an interval needs new numbers, not a new model.

The symbols are appended to the model's disturbance vector (``ModelSpec.parameter_symbols``):
- the named, fitted parameters: the coefficients effects read (:data:`COEFFICIENTS`), the lab
  mill's fitted fields (``lab_`` + :data:`MILL_FIELDS`; the power factor also scales every rate,
  S = S^E P / H, Herbst & Fuerstenau 1980), and the breakage map's parameters, which enter the
  selection vector as a factor on all rates and a change of Austin's size exponent alpha
  (:func:`selection_shift`);
- each component's selection vector and breakage matrix (its lower triangle), whose numbers
  come from the calibration's breakage map (:meth:`ParametricTwin.set_breakage`).
Each evaluation is a Newton solve from the last solution and, for a fit, one extra solve for
the exact sensitivities of P80, specific energy and throughput to every parameter (implicit
function theorem, :func:`twin.solve.steady_sensitivities`).
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np

from ..breakage import SELECTION_REFERENCE_UM, OreBreakage, ore_breakage
from ..errors import TwinInputError
from ..mill import Mill, bond_power_kw
from ..model import Model
from ..solve import steady_sensitivities, steady_state, steady_state_at_load
from .breakage_map import AUSTIN_SHAPE, HARDNESS_REFERENCE_GPA

COEFFICIENTS = ("cushioning_rate_coeff", "slurry_power_coeff", "clay_crowding_coeff")
MILL_FIELDS = ("power_factor", "grate_d50_um", "grate_sharpness", "discharge_factor")
#: Parameters of each breakage map that the selection vector carries (module docstring).
MAP_PARAMETERS = {"dem": ("dem_capture_scale",),
                  "mineralogy": ("se_ref_t_kwh", "hardness_exponent", "texture_exponent", "alpha_texture_exponent")}
#: The reference table's conditions: 70 % of critical speed, the nominal hold-up.
TABLE_SPEED_FRAC_CRITICAL = 0.70
TABLE_LOAD_FRAC = 1.0


class _Symbol(ca.SX):
    """A CasADi symbol that formats as its name (effects write their values into model notes)."""

    def __format__(self, spec: str) -> str:
        return f"<{self.name()}>"


@dataclasses.dataclass(frozen=True)
class SymbolicMill(Mill):
    """A Mill whose fitted fields may be CasADi symbols (its range checks are for numbers)."""

    def __post_init__(self):
        pass


def selection_shift(breakage_map: str, ore, p: dict, base: dict):
    """(ln of the factor on every selection rate, change of alpha) for the map's parameters
    ``p`` (symbols or numbers) against ``base``; mill power factor included."""
    ln_rate, d_alpha = 0.0, 0.0
    if "lab_power_factor" in p:
        ln_rate += ca.log(p["lab_power_factor"]) - math.log(base["lab_power_factor"])
    if breakage_map == "dem":
        if "dem_capture_scale" in p:
            ln_rate += ca.log(p["dem_capture_scale"]) - math.log(base["dem_capture_scale"])
        return ln_rate, d_alpha
    # the mineralogy map (twin.calibration.breakage_map)
    lh, lt = math.log(HARDNESS_REFERENCE_GPA / ore.hardness_index_gpa), math.log(ore.textural_index)
    terms = {"se_ref_t_kwh": lambda v: ca.log(v) if isinstance(v, ca.SX) else math.log(v),
             "hardness_exponent": lambda v: v * lh, "texture_exponent": lambda v: -v * lt}
    for name, term in terms.items():
        if name in p:
            ln_rate += term(p[name]) - term(base[name])
    if "alpha_texture_exponent" in p:
        a0 = AUSTIN_SHAPE["alpha"]
        d_alpha = a0 * ca.exp(p["alpha_texture_exponent"] * lt) - a0 * math.exp(base["alpha_texture_exponent"] * lt)
    return ln_rate, d_alpha


def calibration_values(calibration) -> dict:
    """The fittable values of a calibration: its coefficients and ``lab_``-prefixed mill values."""
    values = dict(calibration.coefficients)
    values.update({f"lab_{k}": v for k, v in calibration.record["mills"].get("lab", {}).items()})
    return values


def fittable(calibration, mill_name: str) -> tuple:
    """The parameters a parametric twin of ``calibration`` in mill ``mill_name`` can carry."""
    lab = tuple(f"lab_{f}" for f in MILL_FIELDS) if mill_name == "lab" else ()
    return COEFFICIENTS + lab + MAP_PARAMETERS[calibration.breakage_map]


class ParametricTwin:
    """A twin of ``ores`` (as :class:`twin.Twin`) with the parameters ``names`` and every
    component's S and b symbolic (module docstring); ``calibration``'s values are the base."""

    def __init__(self, ores, calibration, names=(), **twin_kwargs):
        from ..twin import Twin

        kw = {"mill": calibration.mill, "effects": calibration.effects, "grid": calibration.grid(),
              "n_mixers": calibration.n_mixers} | twin_kwargs
        twin = Twin(ores, calibration=calibration, **kw)
        bad = [n for n in names if n not in fittable(calibration, twin.mill.name)]
        if bad:
            raise TwinInputError(f"Cannot carry {bad} symbolically with breakage map {calibration.breakage_map!r} "
                                 f"in mill {twin.mill.name!r}; possible: {list(fittable(calibration, twin.mill.name))}.")
        self.names, self.twin, self.calibration = tuple(names), twin, calibration
        self.base = calibration_values(calibration)
        self._power_kw = bond_power_kw(twin.mill, twin.mill.speed_nominal_frac_critical)  # as Twin's S^E P/H
        sym = {n: _Symbol(ca.SX.sym(n)) for n in self.names}
        coef = dict(twin.spec.coefficients) | {n: sym[n] for n in self.names if n in COEFFICIENTS}
        fields = {f.name: getattr(twin.mill, f.name) for f in dataclasses.fields(Mill)}
        fields.update({f: sym[f"lab_{f}"] for f in MILL_FIELDS if f"lab_{f}" in sym})
        n = twin.grid.count
        self._tril = np.tril_indices(n, -1)
        x_rel = np.log(twin.grid.mid_um / SELECTION_REFERENCE_UM)
        breakage, self._breakage_syms = [], []
        for c, (ore, ob) in enumerate(zip(twin.blend.ores, twin.spec.breakage)):
            s, b_entries = ca.SX.sym(f"S_{c}", n), ca.SX.sym(f"b_{c}", len(self._tril[0]))
            b = ca.SX(n, n)
            for k, (i, j) in enumerate(zip(*self._tril)):
                b[int(i), int(j)] = b_entries[k]
            ln_rate, d_alpha = selection_shift(calibration.breakage_map, ore, sym, self.base)
            breakage.append(OreBreakage(s * ca.exp(ln_rate + d_alpha * x_rel), b, ob.params))
            self._breakage_syms += [s, b_entries]
        self._breakage = self._breakage_numbers(twin.spec.breakage)
        spec = dataclasses.replace(twin.spec, mill=SymbolicMill(**fields), coefficients=coef, breakage=breakage,
                                   parameter_symbols=ca.vertcat(*sym.values(), *self._breakage_syms),
                                   parameter_values=tuple(self.base[k] for k in self.names) + tuple(self._breakage))
        self.model = Model(spec)
        self._last = None  # (x, feed) of the last solution: the next Newton's start

    def _breakage_numbers(self, ore_breakages) -> np.ndarray:
        return np.concatenate([np.r_[ob.selection_per_h, ob.b[self._tril]] for ob in ore_breakages])

    def set_breakage(self, calibration) -> None:
        """Take S and b of every component from ``calibration``'s map (its laws) at the base
        values of the named parameters (those enter through the symbols), scaled from the
        calibrated mill to this twin's as :class:`twin.Twin` scales them."""
        params = [self.twin.scaled_breakage(calibration.breakage(o)) for o in self.twin.blend.ores]
        holdup = self.twin.spec.holdup_nominal_t
        self._breakage = self._breakage_numbers([ore_breakage(self.twin.grid, p, self._power_kw, holdup)
                                                 for p in params])

    def reset(self) -> None:
        """Forget the last solution: the next solve starts from the nominal guess."""
        self._last = None

    def d(self, values: dict, blend=None) -> np.ndarray:
        w = self.twin.nominal_blend if blend is None else np.asarray(blend, float)
        return np.concatenate([w, [1.0], [float(values[n]) for n in self.names], self._breakage])

    def steady(self, values: dict, feed_tph: float | None = None, speed_frac_critical: float | None = None,
               blend=None, at_load: float | None = None):
        """The steady state at the given numbers: at a feed rate, or (``at_load``) at that load
        with the feed solved for; Newton starts from the last solution."""
        mill = self.twin.mill
        speed = mill.speed_nominal_frac_critical if speed_frac_critical is None else speed_frac_critical
        d = self.d(values, blend)
        guess = None if self._last is None else self._last[0]
        if at_load is None:
            ss = steady_state(self.model, np.array([mill.feed_nominal_tph if feed_tph is None else feed_tph, speed]),
                              d, x_guess=guess)
        else:
            feed0 = mill.feed_nominal_tph if self._last is None else self._last[1]
            ss = steady_state_at_load(self.model, np.array([feed0, speed]), d, at_load, x_guess=guess)
        self._last = (ss.x, ss.feed_tph)
        return ss

    def kpis(self, values: dict, with_gradient: bool = True):
        """The table's KPIs at constant load and 70 % critical, and (``with_gradient``) their
        derivatives in the named parameters: ({kpi: value}, {kpi: gradient over names})."""
        ss = self.steady(values, speed_frac_critical=TABLE_SPEED_FRAC_CRITICAL, at_load=TABLE_LOAD_FRAC)
        kpis = {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                "throughput_kg_h": ss.feed_tph * 1000.0}
        if not with_gradient:
            return kpis, None
        first = self.model.n_components + 1
        sens = steady_sensitivities(self.model, ss, at_load=True, n_d=first + len(self.names))
        cols = slice(first, None)
        grad = {"p80_um": sens["p80_um"][cols], "specific_energy_kwh_t": sens["specific_energy_kwh_t"][cols],
                "throughput_kg_h": 1000.0 * sens["feed_tph"][cols]}
        return kpis, grad
