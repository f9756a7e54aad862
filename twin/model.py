"""The mill model: a CasADi ODE assembled from a list of effects.

Units inside the model (well scaled for the solvers): mass t, time h, size um, power kW,
flows t/h. States: mass of each ore component c in each mixer k and size class i
(``m[c, k, i]``, component-major), then the states effects add (e.g. analyser lags).
Inputs u = [feed_tph, speed_frac_critical]; disturbances d = [blend fraction of each
component..., hardness_scale] (hardness_scale divides every selection rate; 1 = as
calibrated; the estimator uses it for unmeasured ore hardness).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca
import numpy as np

from .effects.base import Build, EffectContext
from .effects.registry import EFFECTS, resolve
from .errors import ModelError, SolverError, TwinInputError, close_matches
from .sizes import SizeGrid, smooth_pxx

INPUT_NAMES = ("feed_tph", "speed_frac_critical")
#: Negative masses down to this share of nominal hold-up are solver round-off and set to zero;
#: anything more negative is a solver failure, reported.
NEGATIVE_ROUNDOFF_REL = 1e-8


@dataclass
class ModelSpec:
    """Everything numeric a model is built from (made by :class:`twin.Twin`)."""

    grid: SizeGrid
    mill: object  # twin.mill.Mill
    component_names: list
    breakage: list  # [OreBreakage] per component
    feed_frac: np.ndarray  # feed size distribution, mass fraction per class
    feed_nominal_tph: float
    holdup_nominal_t: float
    solids_density_t_m3: float  # the nominal blend's: the nominal hold-up's, and the reported parameters'
    soft_frac: list  # clay + mica + chlorite mass fraction per component (twin.ore.minerals)
    clay_frac: list  # clay (kaolinite + illite) mass fraction per component
    coefficients: dict
    n_mixers: int = 3
    mixer_fracs: tuple = ()  # each mixer's share of the hold-up (empty: n_mixers equal shares)
    p80_initial_um: float = 200.0
    #: Each component's solids density [t/m3] (empty: all ``solids_density_t_m3``): a mill fills by volume and
    #: its classifiers settle by density, so the content's own density is read where the nominal blend's was.
    component_density_t_m3: tuple = ()
    effects: list = field(default_factory=list)
    effect_options: dict = field(default_factory=dict)
    #: Symbols (an SX column) appended to d, and their values: a parametric model whose
    #: calibration parameters stay symbolic for exact sensitivities (twin.calibration.parametric).
    parameter_symbols: object = None
    parameter_values: tuple = ()

    def volume_weights(self) -> list[float] | None:
        """rho_nom / rho_c per component (a component's tonnes as tonnes of the nominal blend's volume), None
        when every component has the nominal density (``component_density_t_m3`` empty or all equal to it)."""
        rho = self.component_density_t_m3
        if not rho or all(r == self.solids_density_t_m3 for r in rho):
            return None
        return [self.solids_density_t_m3 / r for r in rho]

    def blend_volume_ratio(self, fractions):
        """The volume of a tonne of a blend (mass ``fractions`` of the components, numbers or CasADi symbols) over
        a tonne's at the nominal density, Σ f_c ρ_nom / ρ_c: the blend's density is the nominal one over it (the
        harmonic mean of its components'); 1.0 when they share the nominal density."""
        weights = self.volume_weights()
        if weights is None:
            return 1.0
        return sum(w * f for w, f in zip(weights, fractions))


class Model:
    """A built mill model: symbols, the ODE right-hand side and named outputs as CasADi
    Functions of (x, u, d). The same object serves plant, estimator and controller.

    It holds exactly what its effects provide: the mass states, the states, algebraic
    aggregates and outputs its effects add (``effect_of`` names the effect of each), and the
    model's own outputs ``holdup_t`` (total hold-up [t]), ``content_p80_um`` and
    ``content_psd_frac`` (the mill content's size distribution). ``p80_um`` is the product's
    P80 and exists only with ``transport``: a batch mill has no product."""

    #: Outputs of every model, whatever its effects.
    CORE_OUTPUTS = ("holdup_t", "content_p80_um", "content_psd_frac")

    def __init__(self, spec: ModelSpec):
        if not spec.mixer_fracs:
            spec.mixer_fracs = tuple([1.0 / spec.n_mixers] * spec.n_mixers)
        if len(spec.mixer_fracs) != spec.n_mixers:
            raise ModelError(f"ModelSpec has {spec.n_mixers} mixers but {len(spec.mixer_fracs)} mixer shares.")
        self.spec = spec
        effects = resolve(spec.effects, spec.effect_options)
        self.effect_names = [e.name for e in effects]
        C, N, n = len(spec.breakage), spec.n_mixers, spec.grid.count
        self.shape = (C, N, n)
        xm = ca.SX.sym("m", C * N * n)
        mass = [[xm[(c * N + k) * n:(c * N + k + 1) * n] for k in range(N)] for c in range(C)]
        self.u = ca.SX.sym("u", len(INPUT_NAMES))
        self.d = ca.SX.sym("d", C + 1)
        if spec.parameter_symbols is not None:
            self.d = ca.vertcat(self.d, spec.parameter_symbols)
        build = Build(spec, self.u, self.d, mass)
        for eff in effects:
            eff.apply(EffectContext(build, eff))
        content = sum(mass[c][k] for c in range(C) for k in range(N))
        build.outputs["holdup_t"] = ca.sum1(content)
        build.outputs["content_p80_um"] = smooth_pxx(spec.grid, content)
        build.outputs["content_psd_frac"] = content / (ca.sum1(content) + 1e-12 * spec.holdup_nominal_t)
        self._build = build
        self.effect_of = {name: build.provider.get(name, "model") for name in build.outputs}
        self.effect_of |= {name: eff for name, (_, _, eff) in build.extra_states.items()}
        blocks = [build.rhs_of(mass[c][k]) for c in range(C) for k in range(N)]
        extra = list(build.extra_states.items())
        self.x = ca.vertcat(xm, *[sym for _, (sym, _, _) in extra])
        xdot_dae = ca.vertcat(*blocks, *[build.rhs_of(sym) for _, (sym, _, _) in extra])
        # aggregates (hold-ups, soft mass, fines) as algebraic variables z = g(x): the DAE form
        # keeps the integrator's Jacobian sparse; substituting z = g(x) gives the plain ODE
        agg = build.aggregates
        self.z = ca.vertcat(*[z for z, _ in agg.values()]) if agg else ca.SX(0, 1)
        self.z_expr = ca.vertcat(*[e for _, e in agg.values()]) if agg else ca.SX(0, 1)
        self.z_names = list(agg)
        self.aggregate_users = {name: sorted(users) for name, users in build.aggregate_users.items()}
        self.dae = {"x": self.x, "z": self.z, "ode": xdot_dae, "alg": self.z - self.z_expr}
        self.xdot = self._substitute(xdot_dae)
        self.psd_what = "product" if "product_tph" in build.outputs else "content"
        self._psd_dae = build.outputs["product_tph"] if self.psd_what == "product" else content
        self._psd = self._substitute(self._psd_dae)
        self.output_exprs_dae = dict(build.outputs)
        self.n_mass = C * N * n
        self.state_groups = [("mass [t]", self.n_mass)] + [(name, sym.numel()) for name, (sym, _, _) in extra]
        self._extra_initial = [init for _, (_, init, _) in extra]
        self.f = ca.Function("f", [self.x, self.u, self.d], [self.xdot], ["x", "u", "d"], ["xdot"])
        self.outputs = {name: ca.Function(name, [self.x, self.u, self.d], [self._substitute(expr)],
                                          ["x", "u", "d"], [name])
                        for name, expr in build.outputs.items()}
        self.parameters = build.parameters
        self.terms = build.terms

    def _substitute(self, expr):
        if self.z.numel() == 0:
            return expr
        return ca.substitute(expr, self.z, self.z_expr)

    def checked_state(self, x, where: str) -> np.ndarray:
        """``x`` with round-off negative masses set to zero; SolverError if it is not finite or a
        mass is negative beyond round-off (mass is never negative)."""
        x = np.array(x, dtype=float)
        if not np.all(np.isfinite(x)):
            raise SolverError(f"Non-finite state in {where}.")
        tol = NEGATIVE_ROUNDOFF_REL * self.spec.holdup_nominal_t
        worst = x[: self.n_mass].min()
        if worst < -tol:
            raise SolverError(f"Negative mass {worst:.3g} t in {where} (beyond round-off {tol:.2g} t): "
                              "tighten the tolerances.")
        x[: self.n_mass] = np.maximum(x[: self.n_mass], 0.0)
        return x

    def z_of(self, x) -> np.ndarray:
        """Values of the algebraic aggregates for a state."""
        if self.z.numel() == 0:
            return np.zeros(0)
        return np.asarray(self._z_function(x), float).ravel()

    @cached_property
    def _z_function(self) -> ca.Function:
        return ca.Function("zx", [self.x], [self.z_expr])

    # ------------------------------------------------------------------ sizes
    @property
    def n_x(self) -> int:
        return self.x.numel()

    @property
    def n_components(self) -> int:
        return self.shape[0]

    def mass_array(self, x) -> np.ndarray:
        """Mass states as an array (component, mixer, class) [t]."""
        return np.asarray(x, dtype=float).ravel()[: self.n_mass].reshape(self.shape)

    def psd_function(self) -> ca.Function:
        """The model's size distribution per class: product flow [t/h], or in a batch model
        (no ``transport``, :attr:`psd_what` ``"content"``) the mill content [t]."""
        return ca.Function("psd", [self.x, self.u, self.d], [self._psd], ["x", "u", "d"], ["psd"])

    def product_psd_function(self) -> ca.Function:
        """Product flow per size class [t/h]; a ModelError in a batch model, which has no product."""
        if self.psd_what != "product":
            raise ModelError("A batch model (no 'transport' effect) has no product; use psd_function() "
                             "for the mill content.")
        return self.psd_function()

    def passing_function(self, size_um: float) -> ca.Function:
        """Fraction of the product passing ``size_um``: linear in the states' flows, so a smooth
        control variable (fraction passing the target size held at 0.80 <=> P80 = target)."""
        w = ca.DM(self.spec.grid.passing_weights(size_um))
        expr = ca.dot(w, self._psd) / (ca.sum1(self._psd) + 1e-12 * self.spec.holdup_nominal_t)
        return ca.Function("passing", [self.x, self.u, self.d], [expr], ["x", "u", "d"], ["passing_frac"])

    # ------------------------------------------------------------------ values
    def d_vector(self, blend_fracs=None, hardness_scale: float = 1.0) -> np.ndarray:
        C = self.n_components
        w = np.ones(C) / C if blend_fracs is None and C > 1 else np.atleast_1d(
            np.asarray(blend_fracs if blend_fracs is not None else [1.0], float))
        if w.shape != (C,):
            raise TwinInputError(f"The 'blend' must have {C} fraction(s), one per component "
                                 f"{self.spec.component_names}. Got {list(w)}.")
        return np.concatenate([w, [hardness_scale], np.asarray(self.spec.parameter_values, float)])

    def u_vector(self, feed_tph: float, speed_frac_critical: float | None = None) -> np.ndarray:
        speed = self.spec.mill.speed_nominal_frac_critical if speed_frac_critical is None else speed_frac_critical
        return np.array([feed_tph, speed], dtype=float)

    def initial_state(self, blend_fracs=None, load_frac: float = 1.0, holdup_t: float | None = None) -> np.ndarray:
        """Mill filled to ``load_frac`` of nominal hold-up (by volume), or holding ``holdup_t`` [t] (a batch's
        charge), with feed of the given blend."""
        C, N, n = self.shape
        w = self.d_vector(blend_fracs)[:C]
        if holdup_t is not None:
            load_frac = holdup_t / self.spec.holdup_nominal_t
        else:  # tonnes of the blend that fill the nominal hold-up's volume
            w = w / self.spec.blend_volume_ratio(w)
        m = np.zeros(self.shape)
        for c in range(C):
            m[c, :, :] = (load_frac * self.spec.holdup_nominal_t * np.asarray(self.spec.mixer_fracs)[:, None]
                          * w[c] * self.spec.feed_frac[None, :])
        return np.concatenate([m.ravel(), *self._extra_initial])

    def evaluate(self, name: str, x, u, d) -> np.ndarray | float:
        if name not in self.outputs:
            raise TwinInputError(f"Unknown output {name!r} of this model.{close_matches(name, self.outputs)} "
                                 f"Outputs: {', '.join(self.outputs)}.")
        val = np.asarray(self.outputs[name](x, u, d), dtype=float).ravel()
        return float(val[0]) if val.size == 1 else val

    @cached_property
    def n_instructions(self) -> int:
        """Operations in the right-hand side: a measure of what the effects cost."""
        return self.f.n_instructions()

    # ------------------------------------------------------------------ report
    def describe(self) -> str:
        """The effects, states, inputs, outputs, parameters and sources actually in the model."""
        lines = [f"Model: {len(self.effect_names)} effect(s), {self.n_x} states, "
                 f"{self.n_instructions} RHS operations"]
        lines.append("Effects:")
        for name in self.effect_names:
            lines.append(f"  {name:15s} {EFFECTS[name].summary}  [{EFFECTS[name].source}]")
        lines.append("Terms:")
        lines += [f"  {t.effect:15s} {t.what}" for t in self.terms]
        lines.append("States: " + ", ".join(f"{g} x{n}" for g, n in self.state_groups)
                     + f"  (components {self.spec.component_names}, {self.shape[1]} mixer(s), "
                       f"{self.shape[2]} size classes)")
        lines.append("Inputs: " + ", ".join(INPUT_NAMES))
        lines.append("Disturbances: " + ", ".join([f"blend_{c}" for c in self.spec.component_names]
                                                   + ["hardness_scale"]))
        lines.append("Outputs: " + ", ".join(f"{name} ({self.effect_of[name]})" for name in self.outputs))
        if self.z_names:
            lines.append("Algebraic aggregates: " + ", ".join(
                f"{name} ({', '.join(self.aggregate_users[name])})" for name in self.z_names))
        if self.parameters:
            lines.append("Parameters:")
            for name, (val, unit, src) in self.parameters.items():
                lines.append(f"  {name} = {val:.6g} {unit}  ({src})")
        return "\n".join(lines)
