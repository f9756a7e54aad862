"""Size classes and size distributions.

Sizes in um. Classes form a geometric series, coarsest first (Austin, Klimpel & Luckie 1984,
*Process Engineering of Size Reduction*, ch. 2): class i holds particles between its upper
size ``upper_um[i] = top_um / ratio**i`` and the next class's upper size; the last class is a
sink holding everything below its upper size. Cumulative passing at an upper size is the mass
in that class and every finer one.

A grid also names how the breakage terms are discretised on it (``scheme``, see
:mod:`twin.breakage`): ``"cell_average"`` (the default, second order in the class width) or
``"austin"`` (the classical discrete form of Austin et al. 1984 and Moly-Cop Tools, first order,
for parameters defined on a tool's own sieve series).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from .errors import TwinInputError, bad_value, check_int, check_range

#: Width (in units of one class's log-size width) over which the smooth P80 blends the
#: kinks of the exact piecewise-linear interpolation; the error this causes is stated in
#: :func:`smooth_pxx` and tested.
SMOOTH_PXX_SHARPNESS = 0.05
#: Discretisations of the breakage terms a grid may name (twin.breakage).
SCHEMES = ("cell_average", "austin")


@dataclass(frozen=True)
class SizeGrid:
    """Geometric size classes: ``count`` classes from ``top_um`` down by ``ratio`` (last is a sink);
    ``scheme`` the discretisation of breakage on them (one of :data:`SCHEMES`)."""

    top_um: float = 6700.0
    ratio: float = math.sqrt(2.0)
    count: int = 25
    scheme: str = "cell_average"

    def __post_init__(self):
        object.__setattr__(self, "top_um", check_range("SizeGrid", "top_um", self.top_um, 0.0, 1e7))
        object.__setattr__(self, "ratio", check_range("SizeGrid", "ratio", self.ratio, 1.0, 10.0, hi_open=False))
        object.__setattr__(self, "count", check_int("SizeGrid", "count", self.count, 3, 400))
        if self.scheme not in SCHEMES:
            raise bad_value("SizeGrid", "scheme", self.scheme, "one of " + ", ".join(map(repr, SCHEMES)))

    @classmethod
    def spanning(cls, top_um: float, bottom_um: float, count: int, scheme: str = "cell_average") -> "SizeGrid":
        """``count`` classes whose upper sizes run from ``top_um`` to ``bottom_um`` (the sink's)."""
        check_range("SizeGrid.spanning", "bottom_um", bottom_um, 0.0, top_um)
        count = check_int("SizeGrid.spanning", "count", count, 3, 400)  # 1 divided by zero
        return cls(top_um, (top_um / bottom_um) ** (1.0 / (count - 1)), count, scheme)

    @property
    def upper_um(self) -> np.ndarray:
        """Upper size of each class [um], coarsest first."""
        return self.top_um / self.ratio ** np.arange(self.count)

    @property
    def lower_um(self) -> np.ndarray:
        """Lower size of each class [um]; 0 for the sink."""
        low = self.upper_um / self.ratio
        low[-1] = 0.0
        return low

    @property
    def mid_um(self) -> np.ndarray:
        """Representative size of each class: geometric mean of its bounds [um]; the sink uses
        the geometric mean of its upper size and one ratio below."""
        return self.upper_um / math.sqrt(self.ratio)

    def passing_weights(self, size_um: float) -> np.ndarray:
        """Weights w with ``sum(w * mass_frac)`` = fraction passing ``size_um``, by linear
        interpolation of cumulative passing in log size between class bounds. Linear in the
        masses, hence usable inside the model as an exact, smooth control variable."""
        size = check_range("SizeGrid", "size_um", size_um, 0.0, math.inf)
        up = self.upper_um
        w = np.zeros(self.count)
        if size >= up[0]:
            return np.ones(self.count)
        if size <= up[-1]:
            # inside the sink: assume the sink's mass is spread as the class above it
            # (geometric), i.e. passing falls by one class per ratio below its upper size
            frac = max(0.0, 1.0 - math.log(up[-1] / size) / math.log(self.ratio))
            w[-1] = frac
            return w
        k = int(np.searchsorted(-up, -size, side="right")) - 1  # up[k] >= size > up[k+1]
        theta = math.log(size / up[k + 1]) / math.log(up[k] / up[k + 1])
        w[k + 1:] = 1.0
        w[k] = theta  # the part of class k below `size`
        return w

    def cumulative_passing(self, mass) -> np.ndarray:
        """Fraction passing each upper size for a mass vector (any units): one finite mass >= 0 per class (a
        vector of another length, a 2-D array or a negative class gave a P80 with no error, 1061 um for 988)."""
        m = np.asarray(mass, dtype=float)
        if m.shape != (self.count,):
            raise TwinInputError(f"The 'mass' of the size grid must hold one mass per class, shape ({self.count},). "
                                 f"Got shape {m.shape}.")
        if not np.all(np.isfinite(m)):
            raise TwinInputError(f"The 'mass' of the size grid must be finite. Got {m.tolist()}.")
        total = m.sum()
        if total <= 0.0 or m.min() < -NEGATIVE_MASS_TOL * total:
            raise TwinInputError(f"Cumulative passing needs masses >= 0 with a positive total. Got total {total:g}, "
                                 f"least class {m.min():g}.")
        return np.cumsum(m[::-1])[::-1] / total


#: A class mass below zero by this much of the total is refused (-0.5 of 1 gave a P80 above the grid's top);
#: less is a solver's round-off or a controller's plan, whose states are unbounded (-2e-4 seen).
NEGATIVE_MASS_TOL = 1e-3


def pxx_um(grid: SizeGrid, mass, percent: float = 80.0) -> float:
    """Size [um] below which ``percent`` % of the mass passes: linear interpolation of cumulative
    passing in log size between class upper sizes (monotone by construction)."""
    frac = check_range("pxx_um", "percent", percent, 1.0, 100.0, lo_open=False) / 100.0  # 0.8 read as P0.8
    passing = grid.cumulative_passing(mass)
    up = grid.upper_um
    if passing[-1] >= frac:  # the sink alone holds it: extrapolate one ratio per class
        return float(up[-1] * grid.ratio ** ((frac - passing[-1]) / max(passing[-1], 1e-300)))
    k = int(np.nonzero(passing >= frac)[0][-1])  # passing[k] >= frac > passing[k+1]
    lo, hi = passing[k + 1], passing[k]
    theta = (frac - lo) / (hi - lo)
    return float(math.exp(math.log(up[k + 1]) + theta * math.log(up[k] / up[k + 1])))


def smooth_pxx(grid: SizeGrid, mass, percent: float = 80.0, sharpness: float = SMOOTH_PXX_SHARPNESS):
    """Differentiable Pxx [um] of a mass vector (numpy or CasADi).

    The exact interpolation is ``ln Pxx = ln x_n + sum_k dlnx * clip(z_k, 0, 1)`` with
    ``z_k = (f - P_{k+1}) / (P_k - P_{k+1})``, the share of interval k lying below the target
    passing f. Replacing ``clip`` by a softplus difference of width ``sharpness`` makes it
    smooth; the error against :func:`pxx_um` is below ``sharpness * ln 2 * ln(ratio)`` in
    ln-size per kink, i.e. < 1.3 % of Pxx at the default sharpness and ratio sqrt 2, and it
    vanishes away from class bounds (tested).
    """
    if isinstance(mass, (ca.SX, ca.MX)):  # the expression is built once per grid (it costs ~10 ms)
        return _smooth_pxx_function(grid, float(percent), float(sharpness))(mass)
    return _smooth_pxx(grid, mass, percent, sharpness)


@lru_cache(maxsize=32)
def _smooth_pxx_function(grid: SizeGrid, percent: float, sharpness: float) -> ca.Function:
    """:func:`smooth_pxx` on ``grid`` as a CasADi function of the mass vector."""
    m = ca.SX.sym("mass", grid.count)
    return ca.Function("smooth_pxx", [m], [_smooth_pxx(grid, m, percent, sharpness)])


def _smooth_pxx(grid: SizeGrid, mass, percent: float, sharpness: float):
    f = percent / 100.0
    n = grid.count
    up = grid.upper_um
    lnr = math.log(grid.ratio)
    is_sym = isinstance(mass, ca.SX)
    m = mass if is_sym else np.asarray(mass, dtype=float)
    total = ca.sum1(m) if is_sym else m.sum()
    exp, log = (ca.exp, ca.log) if is_sym else (np.exp, np.log)
    eps_mass = 1e-12

    def softclip(z):
        s = sharpness
        sp = (lambda v: ca.log1p(ca.exp(-ca.fabs(v))) + ca.fmax(v, 0)) if is_sym else \
             (lambda v: np.log1p(np.exp(-np.abs(v))) + np.maximum(v, 0))
        return s * (sp(z / s) - sp((z - 1.0) / s))

    # cumulative passing at each upper size, finest first accumulation
    ln_p = math.log(up[-1]) - lnr  # start one ratio below the sink's upper size
    acc = 0
    passing = []
    for i in range(n - 1, -1, -1):
        acc = acc + m[i]
        passing.append(acc)
    passing = passing[::-1]  # passing[i] = mass at or below class i (unnormalised)
    # sink interval [up[-1]/ratio, up[-1]]: sink mass spread uniformly in ln size
    intervals = [(passing[n - 1], 0 * total)] + [(passing[k], passing[k + 1]) for k in range(n - 2, -1, -1)]
    for hi, lo in intervals:
        z = (f * total - lo) / (hi - lo + eps_mass * (total + eps_mass))
        ln_p = ln_p + lnr * softclip(z)
    return exp(ln_p)


# ---------------------------------------------------------------- feed size distributions

@dataclass(frozen=True)
class RosinRammler:
    """Cumulative passing ``1 - exp(-(x/x63)^n)`` (Rosin & Rammler 1933); ``x63_um`` > 0 [um], ``n`` > 0."""

    x63_um: float
    n: float

    def __post_init__(self):  # a NaN or negative size made every class fraction NaN, without an error
        check_range("RosinRammler", "x63_um", self.x63_um, 0.0, math.inf)
        check_range("RosinRammler", "n", self.n, 0.0, math.inf)

    def passing(self, x_um):
        return 1.0 - np.exp(-(np.asarray(x_um, dtype=float) / self.x63_um) ** self.n)

    @classmethod
    def from_p80(cls, p80_um: float, n: float = 1.0) -> "RosinRammler":
        check_range("RosinRammler.from_p80", "p80_um", p80_um, 0.0, math.inf)
        check_range("RosinRammler.from_p80", "n", n, 0.0, math.inf)
        return cls(p80_um / math.log(5.0) ** (1.0 / n), n)


#: The largest Gates-Gaudin-Schuhmann modulus allowed: crushed ores lie at 0.5-1.5 (Gupta & Yan
#: 2016, ch. 3); far beyond, the feed is one size and the value a slip (80 for 0.80).
GGS_MODULUS_MAX = 20.0


@dataclass(frozen=True)
class GatesGaudinSchuhmann:
    """Cumulative passing ``min(1, (x/x_max)^m)`` (Gates-Gaudin-Schuhmann); ``x_max_um`` > 0 [um],
    ``m`` in (0, :data:`GGS_MODULUS_MAX`) (a Twin's ``feed_modulus``)."""

    x_max_um: float
    m: float

    def __post_init__(self):  # a NaN or negative size made every class fraction NaN, without an error
        check_range("GatesGaudinSchuhmann", "x_max_um", self.x_max_um, 0.0, math.inf)
        check_range("GatesGaudinSchuhmann", "m", self.m, 0.0, GGS_MODULUS_MAX)

    def passing(self, x_um):
        return np.minimum(1.0, (np.asarray(x_um, dtype=float) / self.x_max_um) ** self.m)

    @classmethod
    def from_p80(cls, p80_um: float, m: float = 0.8) -> "GatesGaudinSchuhmann":
        """The distribution whose P80 is ``p80_um`` [um] (a Twin's ``feed_p80_um``) with modulus ``m``."""
        o = "GatesGaudinSchuhmann.from_p80 (a Twin's feed_p80_um and feed_modulus)"
        check_range(o, "p80_um", p80_um, 0.0, math.inf)
        check_range(o, "m", m, 0.0, GGS_MODULUS_MAX)  # m = 0 divided by zero
        return cls(p80_um * 0.8 ** (-1.0 / m), m)


#: A screen analysis whose every sieve passes at most this many percent is refused by
#: :meth:`TabulatedPSD.from_sieves`: it is fractions given as percentages (0.94 for 94 %), and read
#: as such it would put nearly all the feed above the coarsest sieve.
PASSING_PCT_AS_FRACTION_MAX = 1.0


@dataclass(frozen=True)
class TabulatedPSD:
    """Cumulative passing measured on sieves (``sizes_um`` increasing, ``passing_frac`` in [0, 1]),
    interpolated linearly in log size. Above the coarsest sieve nothing is retained once 100 %
    passes (else the rest lies in the top class, as :func:`discretise` puts it). Below the finest
    sieve the distribution follows the Gates-Gaudin-Schuhmann line through the two finest sieves
    whose passing differs (passing ~ x^m, Gupta & Yan 2016, ch. 3: the straight fine end of crushed
    and ground ores on log-log axes), so the pan is not lumped at one size: through two sieves of
    equal passing (nothing retained on the finest) the line was flat, and the pan's ~24 % lay at
    size zero."""

    sizes_um: tuple
    passing_frac: tuple

    def __post_init__(self):
        s, p = np.asarray(self.sizes_um, float), np.asarray(self.passing_frac, float)
        # NaN compares false: a NaN size or passing went through to NaN class fractions
        if s.ndim != 1 or s.shape != p.shape or s.size < 2 or not np.all(np.isfinite(s)) or np.any(s <= 0) \
                or np.any(np.diff(s) <= 0):
            raise bad_value("TabulatedPSD", "sizes_um", np.ravel(s).tolist(),
                            ">= 2 strictly increasing positive sieve sizes [um], one passing_frac each")
        if not np.all(np.isfinite(p)) or np.any(np.diff(p) < 0) or p[0] <= 0 or p[-1] > 1:
            raise bad_value("TabulatedPSD", "passing_frac", list(self.passing_frac),
                            "fractions passing (0.5, not 50) non-decreasing with size, within (0, 1]")
        if p[-1] == p[0]:  # no slope for the fine end: all of it below the finest sieve, or none on any sieve
            raise bad_value("TabulatedPSD", "passing_frac", list(self.passing_frac),
                            "a passing that rises between some two sieves (all equal: the sieves measure nothing "
                            "of the distribution; give finer sieves)")
        # copies as tuples: the caller's lists edited later went round these checks (passing 5.0 at 600 um)
        object.__setattr__(self, "sizes_um", tuple(float(v) for v in s))
        object.__setattr__(self, "passing_frac", tuple(float(v) for v in p))

    @classmethod
    def from_sieves(cls, sizes_um, passing_pct) -> "TabulatedPSD":
        """From sieve sizes [um] and cumulative % passing in any order (as a screen analysis is
        written, coarsest first); % as 94.43, not 0.9443."""
        s, p = np.asarray(sizes_um, float), np.asarray(passing_pct, float)
        if s.ndim != 1 or s.size < 2 or not np.all(np.isfinite(s)) or np.any(s <= 0):  # a NaN size blamed the passing
            raise bad_value("TabulatedPSD", "sizes_um", s.tolist(), "a flat sequence of >= 2 positive sieve sizes [um]")
        if s.shape != p.shape:
            raise bad_value("TabulatedPSD", "passing_pct", p.tolist(), f"one value per sieve ({s.size} sieves)")
        if not np.all(np.isfinite(p)) or np.any(p < 0) or np.any(p > 100):
            raise bad_value("TabulatedPSD", "passing_pct", p.tolist(), "percentages in [0, 100]")
        if p.size and p.max() <= PASSING_PCT_AS_FRACTION_MAX:  # 0.94 read as 0.94 %: the feed piled above the top sieve
            raise bad_value("TabulatedPSD", "passing_pct", p.tolist(),
                            f"percentages passing (94.43, not 0.9443); all are <= {PASSING_PCT_AS_FRACTION_MAX:g} %, "
                            "fractions of 1 by their look: give them times 100")
        order = np.argsort(s)
        s, p = s[order], p[order]
        # checked here in percent: the fractions' own check spoke of "0.5, not 50" to a user who gave percent
        if np.any(np.diff(s) <= 0):
            raise bad_value("TabulatedPSD", "sizes_um", s.tolist(), "distinct sieve sizes [um]")
        if np.any(np.diff(p) < 0) or p[0] <= 0:
            raise bad_value("TabulatedPSD", "passing_pct", p.tolist(),
                            "cumulative % passing, non-decreasing with sieve size and above 0 at the finest sieve "
                            f"(sizes {s.tolist()} um; % retained on each sieve is not % passing)")
        if p[-1] == p[0]:
            raise bad_value("TabulatedPSD", "passing_pct", p.tolist(), "a % passing that rises between some two "
                            "sieves (all equal: the sieves measure nothing of the distribution; give finer sieves)")
        return cls(tuple(s), tuple(p / 100.0))

    @classmethod
    def from_csv(cls, path) -> "TabulatedPSD":
        """From a CSV file with columns ``size_um`` and ``passing_pct`` (one sieve a row; UTF-8, comma-separated,
        decimal points; lines starting with '#' are comments, as in a scene's history: :func:`twin.atomic.csv_text`)."""
        return cls.read_csv(path)[0]

    @classmethod
    def read_csv(cls, path) -> tuple["TabulatedPSD", str]:
        """:meth:`from_csv`, and the sha256 of the bytes it was read from (read once: a run records the file it was
        fed, as it records a history's)."""
        import io

        import pandas as pd

        from .atomic import csv_text, read_once

        data, sha256 = read_once(path)
        try:
            frame = pd.read_csv(io.StringIO(csv_text(data)), keep_default_na=False, na_values=[""])
        except ValueError as exc:  # a row with a cell more than the header (a decimal comma), not UTF-8, empty
            raise TwinInputError(f"The size-distribution file {path} cannot be read as a comma-separated UTF-8 file "
                                 f"with decimal points: {exc}") from None
        missing = {"size_um", "passing_pct"} - set(frame.columns)
        if missing:
            raise TwinInputError(f"The size-distribution file {path} must have columns size_um and passing_pct. "
                                 f"Missing {sorted(missing)}; found {list(frame.columns)}.")
        values = []
        for col in ("size_um", "passing_pct"):
            num = pd.to_numeric(frame[col], errors="coerce")
            text = (frame[col].notna() & num.isna()).to_numpy()  # a text cell ("Bad", "#N/A") raised a traceback
            if text.any():
                rows = (np.flatnonzero(text) + 1).tolist()
                raise TwinInputError(f"The size-distribution file {path}: column {col} is not a number in data rows "
                                     f"{rows} (e.g. {frame[col][text].iloc[0]!r}); allowed: a number in every row")
            values.append(num.to_numpy(float))
        return cls.from_sieves(*values), sha256

    @property
    def fine_modulus(self) -> float:
        """GGS modulus of the fine end: the log-log slope through the two finest sieves whose passing
        differs (the construction refuses a table with none)."""
        s, p = self.sizes_um, self.passing_frac
        k = next(i for i in range(len(p) - 1) if p[i + 1] > p[i])
        return math.log(p[k + 1] / p[k]) / math.log(s[k + 1] / s[k])

    def passing(self, x_um):
        s, p = np.log(self.sizes_um), np.asarray(self.passing_frac, float)
        x = np.asarray(x_um, float)
        lx = np.log(np.maximum(x, 1e-300))
        inside = np.interp(lx, s, p)  # p[-1] above the coarsest sieve: a jump to 1 there made the feed finer
        fine = p[0] * np.exp(self.fine_modulus * (lx - s[0]))
        return np.where(lx < s[0], fine, inside)


#: Round-off allowed in a distribution's passing fractions by :func:`discretise`.
DISCRETISE_TOL = 1e-9


def discretise(grid: SizeGrid, psd) -> np.ndarray:
    """Mass fraction in each class of a cumulative-passing distribution; mass above the top
    size is put in the top class so the fractions sum to 1 exactly."""
    passing = np.asarray(psd.passing(grid.upper_um), dtype=float)
    # a distribution of the user's own: NaN, percentages or a passing that falls with size were
    # clipped and renormalised into some other feed without a word
    if passing.shape != (grid.count,) or not np.all(np.isfinite(passing)) or np.any(passing < -DISCRETISE_TOL) \
            or np.any(passing > 1.0 + DISCRETISE_TOL) or np.any(np.diff(passing) > DISCRETISE_TOL):
        raise TwinInputError(f"The size distribution {type(psd).__name__} must give from passing(x_um) one fraction "
                             f"passing (0.8, not 80) per size, within [0, 1] and not decreasing with size. Got "
                             f"{np.ravel(passing).tolist()} at the grid's upper sizes {grid.upper_um.tolist()} um.")
    frac = np.empty(grid.count)
    frac[:-1] = passing[:-1] - passing[1:]
    frac[-1] = passing[-1]
    frac[0] += 1.0 - passing[0]
    frac = np.clip(frac, 0.0, None)
    return frac / frac.sum()
