"""Fracture-energy distributions from single-particle breakage results.

Each particle of a size class breaks at its own mass-specific fracture energy E [J/kg]
(slow compression: energy absorbed up to the first fracture; or from the DEM's virtual tests).
Following Tavares & King (1998, Int. J. Miner. Process. 54, 1-28) the energies of one ore
type and size class are described by

- a **log-normal** distribution: ``P(E) = Phi(ln(E / E50) / sigma)``, the probability that a
  particle breaks at a specific energy up to E (Phi the standard normal CDF, E50 the median);
  maximum-likelihood estimates in closed form, ``ln E50 = mean(ln E)``,
  ``sigma = std(ln E)`` (ddof = 0), with standard errors ``sigma/sqrt(n)`` (of ln E50) and
  ``sigma/sqrt(2n)`` (of sigma);
- or an **upper-truncated log-normal** (Tavares & King 1998): ``P(E) = Phi(ln(E*/E50)/sigma)``
  with ``E* = E E_max / (E_max - E)``, for materials whose weakest-flaw population is bounded so
  that every particle breaks below E_max. Fitted by profile maximum likelihood over E_max
  (E50 and sigma closed form given E_max). The likelihood grows without bound as E_max
  approaches the largest observed energy (as for any threshold parameter), so E_max is
  searched on ``max(E) (1 + exp(t))``, t in [-6, 8]; a maximum at the upper end means no
  evidence of truncation and the plain log-normal is the model to use.

Goodness of fit: Kolmogorov-Smirnov statistic against the fitted CDF. Its textbook p-value
assumes parameters fixed in advance and is too optimistic for fitted ones (Lilliefors 1967);
``n_boot > 0`` replaces it by a parametric-bootstrap p-value (refit on each resample).

Drop-weight tests at set energies give pass/fail outcomes instead of energies; the same
``P(E)`` is then fitted by a probit maximum likelihood (:func:`fit_breakage_outcomes`).

Size dependence of the median (Tavares & King 1998): ``E50(d) = E_inf (1 + (d0 / d)^phi)``,
fitted across size classes by least squares on ln E50 (:func:`fit_size_dependence`).

Units: energies J/kg, particle sizes mm. A single-particle table's energies and sizes must lie in the
ranges of such tests (:data:`FRACTURE_ENERGY_RANGE_J_KG`, :data:`PARTICLE_SIZE_RANGE_MM`): outside, the
value is the mark of another unit (kWh/t, um) and the row is refused with the likely one named.
"""

from __future__ import annotations

import io
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import least_squares, minimize, minimize_scalar
from scipy.special import ndtr

from ..errors import TwinInputError, bad_value
from .labels import clean_labels

_MODELS = ("lognormal", "truncated_lognormal")

#: Specific fracture energies of single-particle tests [J/kg]. Low end: -25+19 mm particles of the
#: reference ores break at tens of J/kg in the DEM's virtual compression tests; 1 J/kg leaves a decade for
#: coarser, weaker particles, and a value in kWh/t (1 kWh/t = 3.6 J/g = 3600 J/kg: tens of J/kg are
#: ~0.01 kWh/t) lies below it. High end: ~10x the JK drop-weight test's highest set energy (2.5 kWh/t =
#: 9000 J/kg; Napier-Munn et al. 1996, Mineral Comminution Circuits, JKMRC), room for fine particles, whose
#: fracture energy rises as size falls (Tavares & King 1998). Not caught: a kWh/t value >= 1 (3600 J/kg).
FRACTURE_ENERGY_RANGE_J_KG = (1.0, 1e5)
#: Particle sizes of single-particle tests [mm]: from micro-compression of ~10 um grains to ~5x the JK
#: drop-weight test's top class (-63+53 mm; Napier-Munn et al. 1996). A size in um written as mm lies
#: above it for every particle coarser than 0.3 mm (21.8 mm -> 21800).
PARTICLE_SIZE_RANGE_MM = (0.01, 300.0)


def breakage_probability(e_j_kg, e50_j_kg: float, sigma: float, e_max_j_kg: float = math.inf):
    """``P(E) = Phi(ln(E*/E50)/sigma)``, E* = E for the log-normal, ``E E_max/(E_max - E)``
    for the upper-truncated one (P = 1 at and above E_max)."""
    e = np.asarray(e_j_kg, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        if math.isinf(e_max_j_kg):
            estar = e
        else:
            estar = np.where(e < e_max_j_kg, e * e_max_j_kg / (e_max_j_kg - e), np.inf)
        z = np.where(e > 0, np.log(np.where(e > 0, estar, 1.0) / e50_j_kg) / sigma, -np.inf)
    p = ndtr(z)
    return float(p) if np.ndim(p) == 0 else p


@dataclass(frozen=True)
class FractureEnergyFit:
    """Fitted fracture-energy distribution of one ore type and size class."""

    model: str
    e50_j_kg: float
    sigma: float
    e_max_j_kg: float           # inf for the log-normal
    n: int
    log_likelihood: float
    ks_statistic: float
    ks_pvalue: float
    ks_pvalue_method: str       # 'asymptotic (parameters taken as known)' or 'parametric bootstrap (N)'
    ln_e50_se: float            # standard error of ln E50 (log-normal formulas)
    sigma_se: float

    def breakage_probability(self, e_j_kg):
        return breakage_probability(e_j_kg, self.e50_j_kg, self.sigma, self.e_max_j_kg)

    def cdf(self, e_j_kg):
        return self.breakage_probability(e_j_kg)

    def quantile(self, p):
        """Specific energy at which a fraction p of particles is broken."""
        estar = self.e50_j_kg * np.exp(self.sigma * stats.norm.ppf(p))
        if math.isinf(self.e_max_j_kg):
            return estar
        return estar * self.e_max_j_kg / (estar + self.e_max_j_kg)

    def sample(self, n: int, random_state=None) -> np.ndarray:
        return sample_fracture_energies(n, self.e50_j_kg, self.sigma, self.e_max_j_kg, random_state)

    def to_dict(self) -> dict:
        return asdict(self)


def sample_fracture_energies(n: int, e50_j_kg: float, sigma: float, e_max_j_kg: float = math.inf,
                             random_state=None) -> np.ndarray:
    """Draw n fracture energies [J/kg] from the (truncated) log-normal, seeded."""
    rng = np.random.default_rng(random_state)
    estar = e50_j_kg * np.exp(sigma * rng.standard_normal(int(n)))
    if math.isinf(e_max_j_kg):
        return estar
    return estar * e_max_j_kg / (estar + e_max_j_kg)


def _check_energies(e) -> np.ndarray:
    e = np.asarray(e, dtype=float).ravel()
    if len(e) < 3:
        raise bad_value("fracture-energy fit", "energies_j_kg", f"{len(e)} values", "at least 3 values")
    bad = ~(np.isfinite(e) & (e > 0))
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        raise bad_value("fracture-energy fit", f"energies_j_kg[{i}]", float(e[i]), "a finite number > 0")
    if np.ptp(np.log(e)) == 0:
        raise bad_value("fracture-energy fit", "energies_j_kg", "identical values", "values with a spread")
    return e


def _lognormal_params(e):
    y = np.log(e)
    mu, sigma = float(y.mean()), float(y.std())
    ll = float(np.sum(stats.norm.logpdf(y, mu, sigma) - y))
    return mu, sigma, ll


def _truncated_params(e, e_max):
    estar = e * e_max / (e_max - e)
    y = np.log(estar)
    mu, sigma = float(y.mean()), float(y.std())
    jac = np.log(e_max ** 2 / (e_max - e) ** 2)
    ll = float(np.sum(stats.norm.logpdf(y, mu, sigma) - y + jac))
    return mu, sigma, ll


def _fit_core(e, model):
    if model == "lognormal":
        mu, sigma, ll = _lognormal_params(e)
        return math.exp(mu), sigma, math.inf, ll
    top = float(e.max())
    t_grid = np.linspace(-6.0, 8.0, 57)
    lls = [_truncated_params(e, top * (1 + math.exp(t)))[2] for t in t_grid]
    i = int(np.argmax(lls))
    lo, hi = t_grid[max(i - 1, 0)], t_grid[min(i + 1, len(t_grid) - 1)]
    res = minimize_scalar(lambda t: -_truncated_params(e, top * (1 + math.exp(t)))[2],
                          bounds=(lo, hi), method="bounded", options={"xatol": 1e-6})
    t = float(res.x) if -res.fun >= lls[i] else float(t_grid[i])
    if t >= t_grid[-1] - 1e-3:  # no evidence of truncation: fall back to the log-normal limit
        mu, sigma, ll = _lognormal_params(e)
        return math.exp(mu), sigma, math.inf, ll
    e_max = top * (1 + math.exp(t))
    mu, sigma, ll = _truncated_params(e, e_max)
    return math.exp(mu), sigma, e_max, ll


def fit_fracture_energy(energies_j_kg, model: str = "lognormal", n_boot: int = 0,
                        random_state=None) -> FractureEnergyFit:
    """Maximum-likelihood fit of a fracture-energy distribution (see the module docstring)."""
    if model not in _MODELS:
        raise bad_value("fit_fracture_energy", "model", model, f"a str among {{{', '.join(map(repr, _MODELS))}}}")
    if int(n_boot) != n_boot or n_boot < 0:
        raise bad_value("fit_fracture_energy", "n_boot", n_boot, "an int >= 0")
    e = _check_energies(energies_j_kg)
    e50, sigma, e_max, ll = _fit_core(e, model)
    cdf = lambda x: breakage_probability(x, e50, sigma, e_max)  # noqa: E731
    ks = stats.kstest(e, cdf)
    d, p = float(ks.statistic), float(ks.pvalue)
    method = "asymptotic (parameters taken as known; optimistic)"
    if n_boot:
        rng = np.random.default_rng(random_state)
        exceed = 0
        for _ in range(int(n_boot)):
            eb = sample_fracture_energies(len(e), e50, sigma, e_max, rng)
            b50, bs, bmax, _ = _fit_core(eb, model)
            db = stats.kstest(eb, lambda x: breakage_probability(x, b50, bs, bmax)).statistic
            exceed += db >= d
        p = float(exceed + 1) / (n_boot + 1)
        method = f"parametric bootstrap ({int(n_boot)})"
    n = len(e)
    return FractureEnergyFit(model, e50, sigma, e_max, n, ll, d, p, method,
                             sigma / math.sqrt(n), sigma / math.sqrt(2 * n))


@dataclass(frozen=True)
class BreakageOutcomeFit:
    """Log-normal fit to pass/fail impacts at set specific energies (drop-weight tests)."""

    e50_j_kg: float
    sigma: float
    n: int
    n_broken: int
    log_likelihood: float

    def breakage_probability(self, e_j_kg):
        return breakage_probability(e_j_kg, self.e50_j_kg, self.sigma)


def fit_breakage_outcomes(energies_j_kg, broken) -> BreakageOutcomeFit:
    """Maximum likelihood of ``P(break | E) = Phi(ln(E/E50)/sigma)`` from single impacts:
    each particle hit once at a set specific energy E [J/kg], ``broken`` True/False (a probit
    regression on ln E; each test is a Bernoulli trial). Needs broken and unbroken particles
    at overlapping energies; with complete separation the ML estimate does not exist."""
    e = np.asarray(energies_j_kg, dtype=float).ravel()
    b = np.asarray(broken, dtype=bool).ravel()
    if e.shape != b.shape or len(e) < 3 or not np.all(np.isfinite(e) & (e > 0)):
        raise bad_value("fit_breakage_outcomes", "energies_j_kg/broken", f"{len(e)} tests",
                        "at least 3 tests with finite energies > 0, one outcome each")
    if b.all() or not b.any():
        raise bad_value("fit_breakage_outcomes", "broken", f"{int(b.sum())} of {len(b)} broken",
                        "both broken and unbroken particles")
    lo, hi = FRACTURE_ENERGY_RANGE_J_KG
    off = np.flatnonzero((e < lo) | (e > hi))
    if off.size:  # drop-weight energies are reported in kWh/t (Ecs): E50 came out 3600x low, labelled J/kg
        i = int(off[0])
        hint = _RANGES[ENERGY_COLUMN][2 if e[i] < lo else 3]
        raise bad_value("fit_breakage_outcomes", f"energies_j_kg[{i}]", float(e[i]),
                        f"in [{lo:g}, {hi:g}] J/kg, the range of single-particle tests ({hint})")
    x = np.log(e)
    if x[b].min() > x[~b].max():
        raise TwinInputError("fit_breakage_outcomes: every broken particle was hit harder than every "
                             "unbroken one (complete separation); E50 is bracketed by "
                             f"[{math.exp(x[~b].max()):.4g}, {math.exp(x[b].min()):.4g}] J/kg but "
                             "sigma cannot be estimated. Test more energies in between.")

    def nll(q):
        mu, ls = q
        z = (x - mu) / math.exp(ls)
        return -float(np.sum(np.where(b, stats.norm.logcdf(z), stats.norm.logsf(z))))

    q0 = [float(np.median(x)), math.log(max(float(x.std()), 0.05))]
    sol = minimize(nll, q0, method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-12, "maxiter": 5000})
    mu, ls = sol.x
    return BreakageOutcomeFit(math.exp(mu), math.exp(ls), len(e), int(b.sum()), -float(sol.fun))


# ---------------------------------------------------------------------- tables of results
ENERGY_COLUMN = "fracture_energy_j_kg"
GROUP_COLUMNS = ("ore_type", "size_mm")
#: column -> (allowed range, unit, hint for a value below, hint for a value above)
_RANGES = {
    ENERGY_COLUMN: (FRACTURE_ENERGY_RANGE_J_KG, "J/kg", "in kWh/t? x 3600 to J/kg; in J/g or kJ/kg? x 1000",
                    "in J/t or mJ/kg? / 1000 to J/kg"),
    "size_mm": (PARTICLE_SIZE_RANGE_MM, "mm", "in m or cm? x 1000 or x 10 to mm", "in um? / 1000 to mm"),
}


def read_single_particle(path: str | Path) -> pd.DataFrame:
    """Single-particle results: CSV (``#`` comments allowed) or Parquet with columns
    ``ore_type``, ``size_mm`` (representative size of the class, e.g. the geometric mean of
    -25+19 mm = 21.8 mm), ``fracture_energy_j_kg`` and optional others (``particle_id``...).
    Every bad row is reported with its row number, particle id, column and value."""
    path = Path(path)
    if not path.is_file():
        raise TwinInputError(f"The single-particle results file must exist. Got {str(path)!r}.")
    if path.suffix.lower() in (".parquet", ".pq"):
        frame = pd.read_parquet(path)
    else:
        lines = path.read_text(encoding="utf-8").splitlines()
        frame = pd.read_csv(io.StringIO("\n".join(ln for ln in lines if not ln.lstrip().startswith("#"))),
                            dtype={"ore_type": str})
    return validate_single_particle(frame, source=str(path))


def validate_single_particle(frame: pd.DataFrame, source: str = "single-particle table") -> pd.DataFrame:
    """A clean copy of a single-particle table (energies and sizes as floats, ore types stripped of
    surrounding spaces) or a TwinInputError naming every bad row: a missing, non-positive or
    out-of-range energy or size (with its likely unit), an empty ore type, and ore types that differ
    only by case or whitespace."""
    missing = [c for c in (*GROUP_COLUMNS, ENERGY_COLUMN) if c not in frame.columns]
    if missing:
        raise TwinInputError(f"{source}: the columns {missing} must be present "
                             f"(found {list(frame.columns)}).")
    problems = []
    # python scalars: a message shows 3, not np.int64(3)
    ident = frame["particle_id"].tolist() if "particle_id" in frame.columns else list(range(1, len(frame) + 1))
    for col, ((lo, hi), unit, below, above) in _RANGES.items():
        raw = frame[col].tolist()
        for i, v in enumerate(pd.to_numeric(frame[col], errors="coerce").to_numpy(float)):
            if not (np.isfinite(v) and v > 0):
                allowed = f"a finite number > 0 {unit}"
            elif not lo <= v <= hi:  # a unit slip: the hint names the likely unit
                hint = below if v < lo else above
                allowed = f"in [{lo:g}, {hi:g}] {unit}, the range of single-particle tests ({hint})"
            else:
                continue
            problems.append(f"row {i + 1} (particle_id={ident[i]!r}): column '{col}' must be "
                            f"{allowed}. Got {raw[i]!r}.")
    ores = frame["ore_type"].tolist()
    blank = frame["ore_type"].isna().to_numpy() | (frame["ore_type"].astype(str).str.strip() == "").to_numpy()
    for i in np.nonzero(blank)[0]:
        problems.append(f"row {i + 1} (particle_id={ident[i]!r}): column 'ore_type' must be "
                        f"a non-empty label. Got {ores[i]!r}.")
    if problems:
        more = [f"... and {len(problems) - 50} more"] if len(problems) > 50 else []  # a unit slip hits every row
        raise TwinInputError(f"{source}: {len(problems)} problem(s):\n  " + "\n  ".join(problems[:50] + more))
    out = frame.copy()
    out[ENERGY_COLUMN] = out[ENERGY_COLUMN].astype(float)
    out["size_mm"] = out["size_mm"].astype(float)
    out["ore_type"] = clean_labels(out["ore_type"], "ore_type", source)
    return out


def fit_by_group(frame: pd.DataFrame, model: str = "lognormal", by=GROUP_COLUMNS,
                 energy_column: str = ENERGY_COLUMN, n_boot: int = 0, random_state=None) -> pd.DataFrame:
    """One fit per ore type and size class: a DataFrame with the group keys, e50_j_kg, sigma,
    e_max_j_kg, n, log_likelihood, ks_statistic, ks_pvalue, standard errors."""
    rows = []
    for keys, g in frame.groupby(list(by), sort=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        fit = fit_fracture_energy(g[energy_column].to_numpy(float), model=model, n_boot=n_boot,
                                  random_state=random_state)
        rec = dict(zip(by, keys))
        rec.update(fit.to_dict())
        rows.append(rec)
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------- size dependence
@dataclass(frozen=True)
class SizeDependence:
    """``E50(d) = E_inf (1 + (d0/d)^phi)`` [J/kg], d in mm (Tavares & King 1998)."""

    e_inf_j_kg: float
    d0_mm: float
    phi: float
    rmse_ln: float

    def e50_j_kg(self, d_mm):
        d = np.asarray(d_mm, dtype=float)
        out = self.e_inf_j_kg * (1.0 + (self.d0_mm / d) ** self.phi)
        return float(out) if out.ndim == 0 else out


def fit_size_dependence(size_mm, e50_j_kg, weights=None) -> SizeDependence:
    """Least squares on ln E50 across size classes (at least 3); ``weights`` e.g. sqrt(n)/sigma
    per class (the inverse standard error of ln E50)."""
    d = np.asarray(size_mm, dtype=float)
    y = np.log(np.asarray(e50_j_kg, dtype=float))
    if d.shape != y.shape or len(d) < 3 or not np.all(np.isfinite(d) & (d > 0)) or not np.all(np.isfinite(y)):
        raise bad_value("fit_size_dependence", "size_mm/e50_j_kg", f"{len(d)} pairs",
                        "at least 3 pairs of positive finite sizes and medians")
    w = np.ones_like(d) if weights is None else np.asarray(weights, dtype=float)

    def resid(q):
        le, ld0, phi = q
        return w * (le + np.log1p((math.exp(ld0) / d) ** phi) - y)

    best = None
    for phi0 in (0.5, 1.0, 2.0):
        for d0 in (d.min() * 0.3, np.median(d), d.max() * 3):
            q0 = [y.min() - 0.1, math.log(d0), phi0]
            sol = least_squares(resid, q0, bounds=([-np.inf, -20, 1e-3], [np.inf, 20, 10]))
            if best is None or sol.cost < best.cost:
                best = sol
    le, ld0, phi = best.x
    rmse = float(np.sqrt(np.mean((resid(best.x) / w) ** 2)))
    return SizeDependence(math.exp(le), math.exp(ld0), float(phi), rmse)
