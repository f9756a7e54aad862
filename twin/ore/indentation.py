"""Nano-indentation: Oliver-Pharr analysis of load-displacement curves, and a curve synthesiser.

Method (Oliver & Pharr 1992, J. Mater. Res. 7(6), 1564-1583; refinements in Oliver & Pharr
2004, J. Mater. Res. 19(1), 3-20):

1. Power-law fit of the upper part of the unloading branch, ``P = alpha (h - h_f)^m``
   (``fit_range`` as fractions of P_max, default 0.5-1.0: the upper half, as the 2004 review
   recommends fitting the upper 25-50 % and above), by least squares in P.
   ``h_max`` is taken where the fitted branch reaches P_max (equal to the measured depth for a
   clean curve, less sensitive to one noisy reading).
2. Unloading stiffness at peak load ``S = dP/dh (h_max) = m alpha (h_max - h_f)^(m-1)``.
3. Contact depth ``h_c = h_max - epsilon P_max / S``, ``epsilon = 0.75`` (paraboloid of
   revolution; the value O&P recommend for a Berkovich tip).
4. Projected contact area from the area function
   ``A(h_c) = C0 h_c^2 + C1 h_c + C2 h_c^(1/2) + C3 h_c^(1/4) + ...``, ``C0 = 24.5`` for an
   ideal Berkovich; C1, C2, ... are calibrated for a real (blunted) tip (:class:`AreaFunction`).
5. Reduced modulus ``E_r = (sqrt(pi) / 2) S / (beta sqrt(A))``: MISSION.md eq. 2 has beta = 1;
   O&P 2004 use beta = 1.034 for a Berkovich tip (``beta`` argument).
6. Hardness ``H = P_max / A``.
7. Sample Young's modulus from ``1/E_r = (1 - nu^2)/E + (1 - nu_i^2)/E_i`` with the indenter's
   E_i, nu_i (diamond: 1141 GPa, 0.07; O&P 1992) and the sample's nu.

Units: load mN, depth nm, area nm^2, stiffness mN/nm; moduli and hardness GPa
(1 mN/nm^2 = 1e6 GPa). An H or E_r outside the range of minerals (:data:`HARDNESS_RANGE_GPA`,
:data:`REDUCED_MODULUS_RANGE_GPA`) is refused: it is the mark of a load or depth in another unit.

:func:`synthesize_curve` builds a curve from known E and H by running the same relations
backwards (Kick's-law loading ``P ~ h^2``, power-law unloading). Recovering E and H from it is a
check of the implementation's self-consistency, not an independent validation: it uses the same
epsilon, beta and area function in both directions. The fused-silica reference values
(E = 72 GPa, nu = 0.17, H ~ 9 GPa; O&P 1992, where fused silica is the calibration material)
enter only through such a synthesised curve here; no measured curve is shipped.
"""

from __future__ import annotations

import io
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import brentq, least_squares, minimize_scalar

from ..errors import TwinInputError, bad_value, check_range
from .labels import clean_labels

GPA_PER_MN_NM2 = 1e6  # 1 mN/nm^2 = 1e-3 N / 1e-18 m^2 = 1e15 Pa

#: Hardness a mineral can have [GPa]. Low end: a tenth of the softest phase of minerals.csv (kaolinite
#: aggregate, 0.25 GPa), below talc, Mohs 1 (Broz, Cook & Whitney 2006, Am. Mineral. 91, 135-142, indent
#: talc to corundum); high end: diamond, Mohs 10 (~100 GPa Vickers), with margin. A load in N written as
#: mN puts H 1000x low, a load in uN 1000x high, a depth in um written as nm 1e6x high.
HARDNESS_RANGE_GPA = (0.02, 150.0)
#: Reduced modulus a mineral can give under a diamond tip [GPa]. Low end: 1/7 of the most compliant
#: phase of minerals.csv (kaolinite aggregate, E = 3.2 GPa, E_r ~3.5), room for porous clays; high end: a
#: diamond sample under the diamond tip, 1/(2 (1 - 0.07^2)/1141) = 573 GPa (O&P 1992's E_i, nu_i), above
#: corundum (Broz 2006). E_r moves with the load by the factor H does: a load in N puts the E_r of every
#: mineral below 500 GPa (all but diamond) under the low end, where H alone misses corundum (~30 GPa / 1000
#: lies inside HARDNESS_RANGE_GPA).
REDUCED_MODULUS_RANGE_GPA = (0.5, 600.0)


#: Young's modulus an indenter tip can have [GPa]: from a steel ball (~200 GPa) with margin to diamond, the
#: stiffest tip (1141 GPa, O&P 1992; 1050-1210 by orientation), with margin. Diamond's 1141 given in Pa
#: (1.141e12) lies above, in TPa (1.141) below; accepted, the Pa value moved fused silica's E by 6 %.
INDENTER_YOUNGS_RANGE_GPA = (100.0, 1300.0)


@dataclass(frozen=True)
class Indenter:
    """Indenter elastic constants (default: diamond, O&P 1992)."""

    youngs_gpa: float = 1141.0
    poisson: float = 0.07
    name: str = "diamond Berkovich"

    def __post_init__(self):
        lo, hi = INDENTER_YOUNGS_RANGE_GPA
        if not lo <= check_range("Indenter", "youngs_gpa", self.youngs_gpa, 0.0, math.inf) <= hi:
            raise bad_value("Indenter", "youngs_gpa", self.youngs_gpa, f"a float in [{lo:g}, {hi:g}] GPa, the "
                            "moduli of indenter tips (diamond 1141 GPa; a value in Pa or TPa?)")
        check_range("Indenter", "poisson", self.poisson, -1.0, 0.5)


DIAMOND = Indenter()


@dataclass(frozen=True)
class AreaFunction:
    """``A(h_c) = c0 h_c^2 + sum_i C_i h_c^(2^(1-i))``, i = 1, 2, ...; A in nm^2, h_c in nm.

    ``coefficients`` = (C1, C2, ...) in nm^(2 - 2^(1-i)); empty for the ideal Berkovich."""

    c0: float = 24.5
    coefficients: tuple = field(default_factory=tuple)

    def __post_init__(self):
        check_range("AreaFunction", "c0", self.c0, 0.0, math.inf)
        object.__setattr__(self, "coefficients", tuple(float(c) for c in self.coefficients))

    def exponents(self) -> list[float]:
        return [2.0 ** (1 - i) for i in range(1, len(self.coefficients) + 1)]

    def area_nm2(self, hc_nm):
        hc = np.asarray(hc_nm, dtype=float)
        a = self.c0 * hc ** 2
        for c, e in zip(self.coefficients, self.exponents()):
            a = a + c * hc ** e
        return a

    def contact_depth_nm(self, area_nm2: float) -> float:
        """Inverse of :meth:`area_nm2` (monotonic for the usual positive coefficients)."""
        if not area_nm2 > 0:
            raise bad_value("AreaFunction", "area_nm2", area_nm2, "a float > 0")
        hi = math.sqrt(area_nm2 / self.c0) * 2 + 10.0
        while self.area_nm2(hi) < area_nm2:
            hi *= 2
        return float(brentq(lambda h: float(self.area_nm2(h)) - area_nm2, 0.0, hi, xtol=1e-12, rtol=1e-14))


BERKOVICH = AreaFunction()


def reduced_modulus_gpa(youngs_gpa: float, poisson: float, indenter: Indenter = DIAMOND) -> float:
    """``E_r`` from the sample's E and nu and the indenter's (O&P 1992 eq. 2)."""
    return 1.0 / ((1 - poisson ** 2) / youngs_gpa + (1 - indenter.poisson ** 2) / indenter.youngs_gpa)


def youngs_from_reduced_gpa(reduced_gpa: float, poisson: float, indenter: Indenter = DIAMOND) -> float:
    """Sample E from ``E_r``; raises if E_r is not below the indenter's own contribution."""
    inv = 1.0 / reduced_gpa - (1 - indenter.poisson ** 2) / indenter.youngs_gpa
    if not inv > 0:
        raise TwinInputError(
            f"The reduced modulus {reduced_gpa:.4g} GPa is not below the limit "
            f"{indenter.youngs_gpa / (1 - indenter.poisson ** 2):.4g} GPa set by the indenter "
            f"({indenter.name}); the sample's E cannot be computed.")
    return (1 - poisson ** 2) / inv


@dataclass(frozen=True)
class IndentationResult:
    """Oliver-Pharr result of one curve (units in the names)."""

    p_max_mn: float
    h_max_nm: float
    h_f_nm: float
    m: float
    alpha_mn_per_nm_m: float
    stiffness_mn_nm: float
    contact_depth_nm: float
    area_nm2: float
    reduced_modulus_gpa: float
    hardness_gpa: float
    youngs_gpa: float
    fit_rmse_mn: float
    fit_points: int

    def to_dict(self) -> dict:
        return asdict(self)


def _unloading(load_mn: np.ndarray, depth_nm: np.ndarray) -> slice:
    p_max = load_mn.max()
    # the unloading starts at the last point of the peak-load plateau (end of a hold)
    at_peak = np.nonzero(load_mn >= p_max * (1 - 2e-3))[0]
    return slice(int(at_peak[-1]), len(load_mn))


def _fit_power_law(h: np.ndarray, p: np.ndarray, h_max: float) -> tuple[float, float, float, float]:
    """Least squares P = alpha (h - hf)^m; returns (alpha, hf, m, rmse). Starting point from a
    profile over hf of the log-linear fit."""
    h_min = h.min()
    span = h.max() - h_min

    def loglin(hf):
        x, y = np.log(h - hf), np.log(p)
        m, la = np.polyfit(x, y, 1)
        return m, la, float(np.sum((np.exp(la + m * x) - p) ** 2))

    lo = h_min - 20 * max(span, 1e-9) - h_max
    res = minimize_scalar(lambda hf: loglin(hf)[2], bounds=(lo, h_min - 1e-6 * max(span, 1.0)),
                          method="bounded", options={"xatol": 1e-9 * max(h_max, 1.0)})
    hf0 = float(res.x)
    m0, la0, _ = loglin(hf0)
    scale = max(h_max, 1.0)

    def resid(q):
        la, m, u = q  # hf = h_min - exp(u) * scale keeps hf below the fitted points
        hf = h_min - math.exp(u) * scale
        return (np.exp(la + m * np.log(h - hf)) - p) / p.max()

    u0 = math.log(max(h_min - hf0, 1e-9 * scale) / scale)
    sol = least_squares(resid, x0=[la0, m0, u0], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=20000)
    la, m, u = sol.x
    hf = h_min - math.exp(u) * scale
    rmse = float(np.sqrt(np.mean((resid(sol.x) * p.max()) ** 2)))
    return math.exp(la), hf, float(m), rmse


def oliver_pharr(load_mn, depth_nm, *, area: AreaFunction = BERKOVICH, epsilon: float = 0.75,
                 beta: float = 1.0, indenter: Indenter = DIAMOND, sample_poisson: float = 0.25,
                 fit_range: tuple = (0.5, 1.0)) -> IndentationResult:
    """Oliver-Pharr analysis of one load [mN] - depth [nm] curve (loading then unloading)."""
    P = np.asarray(load_mn, dtype=float)
    h = np.asarray(depth_nm, dtype=float)
    if P.shape != h.shape or P.ndim != 1 or len(P) < 6:
        raise bad_value("oliver_pharr", "load_mn/depth_nm", f"arrays of shapes {P.shape}, {h.shape}",
                        "two 1-D arrays of equal length >= 6")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(h))):
        raise bad_value("oliver_pharr", "load_mn/depth_nm", "non-finite values", "finite numbers")
    check_range("oliver_pharr", "epsilon", epsilon, 0.0, 1.0, hi_open=False)
    check_range("oliver_pharr", "beta", beta, 0.0, 2.0)
    check_range("oliver_pharr", "sample_poisson", sample_poisson, -1.0, 0.5)
    lo, hi = (float(x) for x in fit_range)
    if not 0.0 <= lo < hi <= 1.0:
        raise bad_value("oliver_pharr", "fit_range", fit_range, "a pair 0 <= lo < hi <= 1 (fractions of P_max)")
    un = _unloading(P, h)
    Pu, hu = P[un], h[un]
    p_max, h_max = float(Pu[0]), float(hu[0])
    if not p_max > 0:
        raise bad_value("oliver_pharr", "load_mn", p_max, "a curve with a positive peak load")
    sel = (Pu >= lo * p_max - 1e-12) & (Pu <= hi * p_max + 1e-12)
    if sel.sum() < 4:
        raise TwinInputError(f"The unloading branch has {int(sel.sum())} points in fit_range "
                             f"{fit_range} of P_max; at least 4 are needed.")
    alpha, hf, m, rmse = _fit_power_law(hu[sel], Pu[sel], h_max)
    # h_max from the fitted branch at P_max: one noisy depth reading does not set S and h_c
    h_max = hf + (p_max / alpha) ** (1.0 / m)
    if not h_max > hf:
        raise TwinInputError(f"The unloading fit gives h_f = {hf:.4g} nm >= h_max = {h_max:.4g} nm.")
    S = m * alpha * (h_max - hf) ** (m - 1)
    hc = h_max - epsilon * p_max / S
    if not hc > 0:
        raise TwinInputError(f"The contact depth h_c = {hc:.4g} nm is not positive (h_max = {h_max:.4g} nm, "
                             f"S = {S:.4g} mN/nm); the curve is not an elastic-plastic indentation.")
    A = float(area.area_nm2(hc))
    er = math.sqrt(math.pi) / 2.0 * S / (beta * math.sqrt(A)) * GPA_PER_MN_NM2
    H = p_max / A * GPA_PER_MN_NM2
    _check_mineral_range(H, er, p_max, h_max)
    E = youngs_from_reduced_gpa(er, sample_poisson, indenter)
    return IndentationResult(p_max, h_max, hf, m, alpha, S, hc, A, er, H, E, rmse, int(sel.sum()))


def _check_mineral_range(h_gpa: float, er_gpa: float, p_max_mn: float, h_max_nm: float) -> None:
    """Refuse an H or E_r no mineral has: a load or depth in another unit than mN and nm gives a
    number with the right shape and a wrong magnitude (a load in N: H = 0.009 GPa for fused silica)."""
    out = [f"{name} {v:.4g} GPa outside [{lo:g}, {hi:g}] GPa" for name, v, (lo, hi) in
           (("hardness", h_gpa, HARDNESS_RANGE_GPA), ("reduced modulus", er_gpa, REDUCED_MODULUS_RANGE_GPA))
           if not lo <= v <= hi]
    if not out:
        return
    low = h_gpa < HARDNESS_RANGE_GPA[0] or er_gpa < REDUCED_MODULUS_RANGE_GPA[0]
    # a load x k scales H and E_r by k, a depth x k by 1/k^2
    hint = ("the load in N, not mN (x 1000 to mN)" if low else
            "the load in uN, not mN (/ 1000 to mN), or the depth in um, not nm (x 1000 to nm)")
    raise TwinInputError(
        f"Oliver-Pharr gives {' and '.join(out)}, the range of minerals from clays and talc to diamond "
        f"(P_max = {p_max_mn:.4g} mN, h_max = {h_max_nm:.4g} nm): likely {hint}. Columns: load_mn "
        "millinewtons, depth_nm nanometres.")


def synthesize_curve(youngs_gpa: float, hardness_gpa: float, *, p_max_mn: float = 10.0,
                     m: float = 1.5, sample_poisson: float = 0.25, indenter: Indenter = DIAMOND,
                     area: AreaFunction = BERKOVICH, epsilon: float = 0.75, beta: float = 1.0,
                     n_load: int = 100, n_unload: int = 100, hold_points: int = 0,
                     hold_creep_nm: float = 0.0, noise_mn: float = 0.0, noise_nm: float = 0.0,
                     random_state=None) -> pd.DataFrame:
    """Load-depth curve of a sample with known E [GPa], H [GPa]: Kick's-law loading
    ``P = P_max (h/h_max)^2``, an optional hold at P_max with creep, power-law unloading with
    exponent ``m`` whose stiffness and contact depth satisfy the Oliver-Pharr relations for the
    given epsilon, beta and area function. Gaussian noise (s.d. noise_mn, noise_nm) seeded by
    ``random_state``. Columns: load_mn, depth_nm, segment ('load', 'hold', 'unload')."""
    check_range("synthesize_curve", "youngs_gpa", youngs_gpa, 0.0, math.inf)
    check_range("synthesize_curve", "hardness_gpa", hardness_gpa, 0.0, math.inf)
    check_range("synthesize_curve", "p_max_mn", p_max_mn, 0.0, math.inf)
    check_range("synthesize_curve", "m", m, 1.0, 3.0)
    A = p_max_mn / hardness_gpa * GPA_PER_MN_NM2
    hc = area.contact_depth_nm(A)
    er = reduced_modulus_gpa(youngs_gpa, sample_poisson, indenter)
    S = er / GPA_PER_MN_NM2 * 2.0 * beta * math.sqrt(A) / math.sqrt(math.pi)
    h_max_unload = hc + epsilon * p_max_mn / S
    h_span = m * p_max_mn / S           # h_max - h_f
    hf = h_max_unload - h_span
    alpha = p_max_mn / h_span ** m
    h_max_load = h_max_unload - hold_creep_nm
    h_load = np.linspace(0.0, h_max_load, n_load)
    P_load = p_max_mn * (h_load / h_max_load) ** 2
    h_hold = np.linspace(h_max_load, h_max_unload, hold_points + 2)[1:-1] if hold_points else np.empty(0)
    h_un = np.linspace(h_max_unload, hf, n_unload)
    P_un = alpha * np.clip(h_un - hf, 0.0, None) ** m
    P = np.concatenate([P_load, np.full(len(h_hold), p_max_mn), P_un])
    h = np.concatenate([h_load, h_hold, h_un])
    seg = ["load"] * n_load + ["hold"] * len(h_hold) + ["unload"] * n_unload
    if noise_mn or noise_nm:
        rng = np.random.default_rng(random_state)
        P = P + rng.normal(0.0, noise_mn, len(P)) if noise_mn else P
        h = h + rng.normal(0.0, noise_nm, len(h)) if noise_nm else h
    return pd.DataFrame({"load_mn": P, "depth_nm": h, "segment": seg})


def read_curves(path: str | Path) -> dict[str, pd.DataFrame]:
    """Curves from a CSV with columns ``depth_nm``, ``load_mn`` and optionally ``curve_id``
    (several curves in one file, in order); ``#`` comment lines allowed. Every non-numeric or
    missing cell is reported with its row and column."""
    path = Path(path)
    if not path.is_file():
        raise TwinInputError(f"The indentation curve file must exist. Got {str(path)!r}.")
    lines = path.read_text(encoding="utf-8").splitlines()
    body = "\n".join(ln for ln in lines if not ln.lstrip().startswith("#"))
    frame = pd.read_csv(io.StringIO(body), dtype={"curve_id": str})
    missing = [c for c in ("depth_nm", "load_mn") if c not in frame.columns]
    if missing:
        raise TwinInputError(f"{path}: the columns {missing} must be present (found {list(frame.columns)}); "
                             "units: depth_nm nanometres, load_mn millinewtons.")
    problems = []
    for col in ("depth_nm", "load_mn"):
        num = pd.to_numeric(frame[col], errors="coerce")
        for i in np.nonzero(~np.isfinite(num.to_numpy(float)))[0][:20]:
            cid = frame["curve_id"].iloc[i] if "curve_id" in frame.columns else ""
            problems.append(f"row {i + 1} (curve_id={cid!r}): column '{col}' must be a finite number. "
                            f"Got {frame[col].iloc[i]!r}.")
        frame[col] = num
    if problems:
        raise TwinInputError(f"{path}: bad cells in the indentation curves:\n  " + "\n  ".join(problems))
    if "curve_id" not in frame.columns:
        frame["curve_id"] = path.stem
    # ' fs-1' and 'fs-1' split one curve in two, each analysed alone
    ids = frame["curve_id"] = clean_labels(frame["curve_id"], "curve_id", str(path))
    starts = ids.ne(ids.shift())  # where a run of one id begins: a curve is one run of rows
    again = ids[starts][ids[starts].duplicated()]
    if len(again):  # grouped, two runs of an id were one curve: load, unload, load, unload, analysed as one
        row = int(again.index[0]) + 1
        raise TwinInputError(f"{path}: curve_id {again.iloc[0]!r} starts again at row {row}, after other curves; "
                             "a curve's rows must be consecutive (give each curve its own id).")
    return {str(cid): g[["load_mn", "depth_nm"]].reset_index(drop=True)
            for cid, g in frame.groupby("curve_id", sort=False)}


def analyse_curves(curves: dict | str | Path, **kwargs) -> pd.DataFrame:
    """Oliver-Pharr result of every curve (a dict id -> DataFrame, or a CSV path), one row each."""
    where = ""
    if not isinstance(curves, dict):
        where = f"{curves}: "
        curves = read_curves(curves)
    rows = []
    for cid, df in curves.items():
        rec = {"curve_id": cid}
        try:
            rec.update(oliver_pharr(df["load_mn"].to_numpy(), df["depth_nm"].to_numpy(), **kwargs).to_dict())
        except TwinInputError as exc:  # which of the file's curves it is
            raise TwinInputError(f"{where}curve_id {cid!r}: {exc}") from None
        rows.append(rec)
    return pd.DataFrame(rows)
