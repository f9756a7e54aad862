"""Selection (breakage-rate) and breakage functions of the population balance model.

Sources:
- Austin L.G., Klimpel R.R., Luckie P.T. (1984) *Process Engineering of Size Reduction: Ball
  Milling*, SME: selection function ``S_i = A (x_i/x0)^alpha / (1 + (x_i/mu)^Lambda)`` (eq. 4.5),
  cumulative breakage function ``B_ij = phi_j (x_{i-1}/x_j)^gamma + (1-phi_j)(x_{i-1}/x_j)^beta``
  (eq. 4.11), non-normalisable ``phi_j = phi_1 (x_j/x_1)^-delta``, and the mill-speed factor
  ``(phi_c - 0.1) / (1 + exp(15.7 (phi_c - 0.94)))`` (eq. 8.4).
- Herbst J.A., Fuerstenau D.W. (1980) Scale-up procedure for continuous grinding mill design
  using population balance models. Int. J. Miner. Process. 7, 1-31: energy-specific selection
  function ``S_i = S_i^E P / H`` (S^E in t/kWh, P net power kW, H hold-up t).

Rates are per hour; sizes in um (x0 = 1000 um).

Discretisation on a grid (``SizeGrid.scheme``):
- ``"cell_average"`` (default): S(y) and B(x/y) are functions of a continuous size; each class's
  rate and each fragment share are integrated over the parent interval (mass uniform in ln y
  within a class, Gauss-Legendre in ln y) and the fragments counted exactly into the daughter
  intervals, including those that stay in the parent's own interval. The error is second order
  in the class width (Kumar & Ramkrishna 1996, Chem. Eng. Sci. 51, 1311-1332, on cell-integrated
  breakage terms; the observed order is tested). Fragments that stay in the parent interval are
  folded into an effective rate, S_j (1 - b_jj), so b stays strictly lower-triangular. Austin's
  rate form (``BreakageParams.interval_rate``) is a measured rate of leaving a sqrt(2) interval,
  all fragments leaving it: the particle rate is raised so that the interval whose top is 1 mm is
  left at that rate (:func:`interval_rate_factor`).
- ``"austin"``: the classical discrete form (Austin et al. 1984, eq. 4.11; Moly-Cop Tools): S at
  the class's geometric mean and B_ij = B(x_i / x_{j+1}), sizes relative to the parent's lower
  bound, all fragments leaving the parent class. First order in the class width; it is the model
  in which a tool's parameters are defined on its own sieve series.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

from .errors import ModelError, TwinInputError, check_range
from .mill import SPEED_FACTOR_ZERO_FRAC_CRITICAL
from .sizes import SizeGrid

#: Reference size of the selection function [um] (Austin's x0 = 1 mm).
SELECTION_REFERENCE_UM = 1000.0
#: Austin's rate form is quoted per sqrt(2) sieve interval at the interval's top size x_i (Austin,
#: Klimpel & Luckie 1984, eq. 4.5: x_i the upper limit of size interval i); the twin's S(x)
#: is a particle size's (a class's geometric mean, or integrated over the class), a factor 2^(1/4)
#: below that top size: A (x 2^(1/4))^alpha / (1 + (x 2^(1/4) / mu)^Lambda) is A 2^(alpha/4) x^alpha /
#: (1 + (x / (mu 2^(-1/4)))^Lambda).
AUSTIN_TOP_OVER_MEAN = 2.0 ** 0.25
#: The smallest critical size of the selection [um] (Austin's mu, Moly-Cop's d_crit) a user may give: ball
#: mills' lie at millimetres (Austin et al. 1984, ch. 4: ~3 mm for 25-mm balls, scaling as the ball size
#: squared, ~0.5 mm for 10-mm balls), while a size in mm (3 for 3 mm) ground nothing: P80 the feed's F80 at
#: 1,900 times the nominal hold-up.
CRITICAL_SIZE_MIN_UM = 100.0
#: Column sums of b must equal 1 to this tolerance (mass conservation, checked on build).
B_COLUMN_TOLERANCE = 1e-12
#: Gauss-Legendre nodes per parent interval of the cell-average scheme: the integrands are
#: smooth power laws in ln y, integrated to ~1e-12 relative by 12 nodes (tested against 48).
GAUSS_NODES = 12


#: BreakageParams' fields under the names of BreakageParams.energy_specific's arguments (Moly-Cop's).
MOLYCOP_NAMES = {"mu_um": "critical_size_um", "Lambda": "alpha2", "gamma": "beta1", "beta": "beta2", "phi": "beta0"}


def exponent_order_problem(gamma: float, beta: float, phi: float, names=("phi", "gamma", "beta")) -> str | None:
    """Why B = phi y^gamma + (1 - phi) y^beta has its exponents out of Austin's order, or None: gamma, the
    fine-fragment term's, is the smaller (Austin, Klimpel & Luckie 1984, ch. 3: gamma ~0.5-1.5, beta ~2.5-5),
    so gamma above beta is the two typed in each other's place. ``names``: phi, gamma, beta as the caller's keys."""
    numbers = all(isinstance(v, Real) and not isinstance(v, bool) for v in (gamma, beta, phi))
    if not (numbers and gamma > beta):  # a value not a number is check_range's to refuse
        return None
    n_phi, n_gamma, n_beta = names
    return (f"{n_gamma} = {gamma:g} is above {n_beta} = {beta:g} (allowed: {n_gamma} <= {n_beta}): {n_gamma} is the "
            "exponent of B's fine-fragment term, "
            f"the smaller (Austin, Klimpel & Luckie 1984, ch. 3: ~0.5-1.5 against ~2.5-5); swapped? The same B in "
            f"that order is {n_phi} = {1.0 - phi:.6g}, {n_gamma} = {beta:g}, {n_beta} = {gamma:g}")


@dataclass(frozen=True)
class BreakageParams:
    """Breakage parameters of one ore at the mill's nominal conditions.

    ``se_1mm_t_kwh``: energy-specific selection at 1 mm [t/kWh]; alpha, mu_um, Lambda: Austin
    selection shape; gamma, beta, phi, delta: cumulative breakage function. ``interval_rate``: the
    selection is Austin's measured rate of leaving a sqrt(2) sieve interval, every fragment leaving
    it (Austin, Klimpel & Luckie 1984, ch. 3-4: the first-order disappearance of a one-interval
    feed; :meth:`austin_rate`), not a particle's rate (module docstring, the cell-average scheme).
    """

    se_1mm_t_kwh: float
    alpha: float = 1.0
    mu_um: float = 3000.0
    Lambda: float = 2.5
    gamma: float = 1.0
    beta: float = 4.0
    phi: float = 0.5
    delta: float = 0.0
    source: str = ""
    interval_rate: bool = False

    def __post_init__(self):
        o = "BreakageParams"
        check_range(o, "se_1mm_t_kwh", self.se_1mm_t_kwh, 0.0, 1e6)
        check_range(o, "alpha", self.alpha, 0.0, 5.0)
        check_range(o, "mu_um", self.mu_um, 0.0, 1e7)  # a mapped mu scaled to 10-mm balls lies below a given one's
        check_range(o, "Lambda", self.Lambda, 0.0, 20.0)
        check_range(o, "gamma", self.gamma, 0.0, 5.0)
        check_range(o, "beta", self.beta, 0.0, 20.0)
        check_range(o, "phi", self.phi, 0.0, 1.0, lo_open=False, hi_open=False)
        check_range(o, "delta", self.delta, -1.0, 5.0, lo_open=False)
        order = exponent_order_problem(self.gamma, self.beta, self.phi)
        if order:
            raise TwinInputError(f"{o}: {order}" + (" (for delta = 0)" if self.delta else ""))

    @classmethod
    def energy_specific(cls, alpha0_t_kwh: float, alpha1: float, alpha2: float, critical_size_um: float,
                        beta0: float, beta1: float, beta2: float, source: str = "") -> "BreakageParams":
        """The energy-specific selection and breakage of Moly-Cop Tools (Sepulveda; Herbst &
        Fuerstenau 1980): S^E = alpha0 d^alpha1 / (1 + (d/d_crit)^alpha2) [t/kWh] with d in um,
        and B = beta0 (x/y)^beta1 + (1 - beta0)(x/y)^beta2, i.e. Austin's phi = beta0,
        gamma = beta1, beta = beta2. Sizes in um: the published BallSim base case (alpha0 0.009686)
        grinds to its published product only so (in mm its mill could not break its feed)."""
        o = "BreakageParams.energy_specific"
        check_range(o, "alpha0_t_kwh", alpha0_t_kwh, 0.0, 1e6)
        check_range(o, "alpha1", alpha1, 0.0, 5.0)
        check_range(o, "critical_size_um", critical_size_um, CRITICAL_SIZE_MIN_UM, 1e7, lo_open=False)
        order = exponent_order_problem(beta1, beta2, beta0, names=("beta0", "beta1", "beta2"))
        if order:
            raise TwinInputError(f"{o}: {order}")
        try:
            return cls(se_1mm_t_kwh=alpha0_t_kwh * SELECTION_REFERENCE_UM ** alpha1, alpha=alpha1,
                       mu_um=critical_size_um, Lambda=alpha2, gamma=beta1, beta=beta2, phi=beta0,
                       source=source or "energy-specific (Moly-Cop) parameters")
        except TwinInputError as exc:  # named by Austin's fields, not the arguments given ('phi' for beta0 = 20)
            text = str(exc)
            for austin, given in MOLYCOP_NAMES.items():
                text = text.replace(f"'{austin}' parameter of BreakageParams",
                                    f"'{given}' parameter of {o} (Austin's {austin})")
            raise TwinInputError(text) from None

    @classmethod
    def austin_rate(cls, a_per_min: float, alpha: float, mu_um: float, Lambda: float, gamma: float, beta: float,
                    phi: float, power_kw: float, holdup_t: float, delta: float = 0.0,
                    source: str = "") -> "BreakageParams":
        """Austin's form with its rate constant A [1/min] of the sqrt(2) interval whose top size is 1 mm,
        measured at a net power [kW] and hold-up [t]: S^E(1 mm) = 60 A H / P (Herbst & Fuerstenau 1980),
        moved from Austin's top sizes to the twin's particle sizes (:data:`AUSTIN_TOP_OVER_MEAN`); the rate is
        the interval's (``interval_rate``)."""
        o = "BreakageParams.austin_rate"
        check_range(o, "a_per_min", a_per_min, 0.0, 1e6)
        check_range(o, "mu_um", mu_um, CRITICAL_SIZE_MIN_UM, 1e7, lo_open=False)
        check_range(o, "power_kw", power_kw, 0.0, math.inf)
        check_range(o, "holdup_t", holdup_t, 0.0, math.inf)
        return cls(se_1mm_t_kwh=60.0 * a_per_min * holdup_t / power_kw * AUSTIN_TOP_OVER_MEAN ** alpha, alpha=alpha,
                   mu_um=mu_um / AUSTIN_TOP_OVER_MEAN, Lambda=Lambda,
                   gamma=gamma, beta=beta, phi=phi, delta=delta, source=source or "Austin parameters (rate form)",
                   interval_rate=True)


def austin_selection(grid: SizeGrid, a_per_h: float, alpha: float, mu_um: float, Lambda: float) -> np.ndarray:
    """Austin selection function [1/h] at each class's representative size (eq. 4.5).
    The sink class does not break (its content is below the grid)."""
    s = selection_at(grid.mid_um, a_per_h, alpha, mu_um, Lambda)
    s[-1] = 0.0
    return s


def selection_maximum_um(alpha: float, mu_um: float, Lambda: float) -> float:
    """Size of the maximum of the Austin selection function [um]: dS/dx = 0 gives
    x_max = mu (alpha / (Lambda - alpha))^(1/Lambda), defined for Lambda > alpha."""
    if Lambda <= alpha:
        raise ModelError(f"The Austin selection function has a maximum only for Lambda > alpha. "
                         f"Got Lambda={Lambda}, alpha={alpha}.")
    return mu_um * (alpha / (Lambda - alpha)) ** (1.0 / Lambda)


def cumulative_breakage(grid: SizeGrid, gamma: float, beta: float, phi: float, delta: float = 0.0) -> np.ndarray:
    """Cumulative breakage function B[i, j]: fraction of the primary product of class j that
    passes the upper size of class i (i > j). All fragments leave the parent class, so
    B[j+1, j] = 1 (Austin's indexing: his x_{i-1}/x_j is our upper(i)/upper(j+1)).
    Non-normalisable when delta != 0."""
    up = grid.upper_um
    n = grid.count
    B = np.zeros((n, n))
    for j in range(n - 1):
        phi_j = min(1.0, phi * (up[j] / up[0]) ** (-delta))
        r = up[j + 1:] / up[j + 1]  # Austin's x_{i-1}/x_j: sizes relative to the parent's lower size
        B[j + 1:, j] = phi_j * r ** gamma + (1.0 - phi_j) * r ** beta
    return B


def breakage_matrix(B: np.ndarray) -> np.ndarray:
    """b[i, j] = B[i, j] - B[i+1, j] (the sink keeps B[n-1, j]); checks mass conservation."""
    b = np.zeros_like(B)
    b[:-1] = B[:-1] - B[1:]
    b[-1] = B[-1]
    b = np.tril(b, -1)
    check_breakage_matrix(b)
    return b


def check_breakage_matrix(b: np.ndarray) -> None:
    """Raise ModelError unless b is non-negative, strictly lower-triangular and each breaking
    column sums to 1 (fragments of class j carry all of its broken mass)."""
    n = b.shape[0]
    if b.shape != (n, n):
        raise ModelError(f"The breakage matrix b must be square. Got shape {b.shape}.")
    if np.any(b < -B_COLUMN_TOLERANCE):
        i, j = np.argwhere(b < -B_COLUMN_TOLERANCE)[0]
        raise ModelError(f"The breakage matrix b must be non-negative. Got b[{i},{j}] = {b[i, j]:.3g}.")
    if np.any(np.abs(np.triu(b)) > 0):
        raise ModelError("The breakage matrix b must be strictly lower-triangular "
                         "(fragments are finer than their parent).")
    sums = b[:, :-1].sum(axis=0)
    bad = np.abs(sums - 1.0) > B_COLUMN_TOLERANCE * n
    if np.any(bad):
        j = int(np.nonzero(bad)[0][0])
        raise ModelError(f"Column {j} of the breakage matrix b must sum to 1 (mass conservation). "
                         f"Got {sums[j]:.15g}.")




def austin_speed_factor(speed_frac_critical):
    """Relative breakage rate against mill speed (Austin et al. 1984, eq. 8.4); works on floats
    and CasADi expressions. Falls steeply above ~0.9 of critical as the charge centrifuges."""
    import casadi as ca

    exp = ca.exp if isinstance(speed_frac_critical, (ca.SX, ca.MX)) else np.exp
    return (speed_frac_critical - SPEED_FACTOR_ZERO_FRAC_CRITICAL) / (1.0 + exp(15.7 * (speed_frac_critical - 0.94)))


@dataclass(frozen=True)
class OreBreakage:
    """Numeric selection vector [1/h] at nominal mill conditions and breakage matrix of one ore."""

    selection_per_h: np.ndarray
    b: np.ndarray
    params: BreakageParams


def selection_at(size_um, a_per_h: float, alpha: float, mu_um: float, Lambda: float):
    """Austin's selection function [1/h] at sizes [um] (eq. 4.5)."""
    x = np.asarray(size_um, float)
    return a_per_h * (x / SELECTION_REFERENCE_UM) ** alpha / (1.0 + (x / mu_um) ** Lambda)


def _interval_average(lo_um: float, hi_um: float, a_per_h: float, params: BreakageParams, top_um: float):
    """Gauss-Legendre nodes y in ln size over [lo, hi] [um], their weights (summing to 1), the particle
    rates S(y) [1/h] times the weights, and breakage's phi at y (``top_um``: the grid's top, delta's)."""
    t, w = np.polynomial.legendre.leggauss(GAUSS_NODES)
    lo, hi = math.log(lo_um), math.log(hi_um)
    y = np.exp(lo + (t + 1.0) / 2.0 * (hi - lo))
    rate = w / 2.0 * selection_at(y, a_per_h, params.alpha, params.mu_um, params.Lambda)
    phi_y = np.minimum(1.0, params.phi * (y / top_um) ** (-params.delta))
    return y, w / 2.0, rate, phi_y


def interval_rate_factor(params: BreakageParams, top_um: float) -> float:
    """What the particle rate of ``params`` (``interval_rate``) is multiplied by on the cell-average
    scheme: the particle rate at the geometric mean of Austin's sqrt(2) interval whose top is 1 mm
    (his rate of leaving it) over the rate at which particles uniform in ln size over that interval
    leave it, <S(y) B(x_lo / y)>, the fragments above x_lo staying. ``top_um``: the grid's top (delta)."""
    hi = SELECTION_REFERENCE_UM
    lo = hi / math.sqrt(2.0)
    y, _, rate, phi_y = _interval_average(lo, hi, 1.0, params, top_um)
    z = lo / y
    leaving = rate @ (phi_y * z ** params.gamma + (1.0 - phi_y) * z ** params.beta)
    return float(selection_at(hi / AUSTIN_TOP_OVER_MEAN, 1.0, params.alpha, params.mu_um, params.Lambda) / leaving)


def cell_average_breakage(grid: SizeGrid, a_per_h: float, params: BreakageParams):
    """Effective selection [1/h] and strictly lower-triangular b of the cell-average scheme (module
    docstring): per parent class j, with mass uniform in ln y over [x_{j+1}, x_j],
    S_j = <S(y) B(x_{j+1}/y)> (the rate of leaving the class) and
    b_ij = <S(y) (B(x_i/y) - B(x_{i+1}/y))> / S_j, the sink's lower size 0; an interval rate
    (``params.interval_rate``) raised by :func:`interval_rate_factor`."""
    up, n = grid.upper_um, grid.count
    if params.interval_rate:
        a_per_h = a_per_h * interval_rate_factor(params, up[0])
    s = np.zeros(n)
    b = np.zeros((n, n))
    for j in range(n - 1):
        y, w, rate, phi_y = _interval_average(up[j + 1], up[j], a_per_h, params, up[0])
        z = up[j + 1:, None] / y[None, :]  # upper sizes of classes j+1..n-1 over the parent size
        passing = phi_y * z ** params.gamma + (1.0 - phi_y) * z ** params.beta
        share = passing - np.vstack([passing[1:], np.zeros((1, y.size))])
        s[j] = rate @ passing[0]
        if s[j] > 0.0:
            b[j + 1:, j] = (share @ rate) / s[j]
        else:
            b[j + 1:, j] = share @ w
    # the columns sum to 1 up to round-off in the difference of passings; make it exact
    b[:, :-1] /= b[:, :-1].sum(axis=0)
    check_breakage_matrix(b)
    return s, b


def ore_breakage(grid: SizeGrid, params: BreakageParams, power_kw: float, holdup_t: float) -> OreBreakage:
    """Selection [1/h] from the energy-specific form S = S^E P / H (Herbst & Fuerstenau 1980)
    at the mill's nominal power and hold-up, and the mass-conserving b, discretised by the grid's
    scheme (module docstring)."""
    check_range("ore_breakage", "power_kw", power_kw, 0.0, math.inf)
    check_range("ore_breakage", "holdup_t", holdup_t, 0.0, math.inf)
    a_per_h = params.se_1mm_t_kwh * power_kw / holdup_t
    if grid.scheme == "austin":
        s = austin_selection(grid, a_per_h, params.alpha, params.mu_um, params.Lambda)
        b = breakage_matrix(cumulative_breakage(grid, params.gamma, params.beta, params.phi, params.delta))
    else:
        s, b = cell_average_breakage(grid, a_per_h, params)
    return OreBreakage(s, b, params)
