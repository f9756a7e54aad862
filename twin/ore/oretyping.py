"""Ore typing by data: scaling, PCA of the modal mineralogy, clustering in PC space.

Pipeline (MISSION.md section 1):

1. **Scaling.** Default ``transform="standard"``: each mineral's wt% centred and divided by its
   standard deviation (StandardScaler), so a minor phase such as chalcopyrite (a few wt%)
   weighs as much as quartz; this is the convention of geometallurgical PCA and gives loadings
   readable as correlations. Alternative ``transform="clr"``: centred log-ratio (Aitchison
   1986, *The Statistical Analysis of Compositional Data*), the proper geometry for closed
   data summing to 100 %, but it needs zeros replaced: each zero by ``detection_limit_wt_pct``
   d, the other parts left as they are. As clr ignores a common factor, this is the
   multiplicative replacement of Martin-Fernandez et al. (2003, Math. Geol. 35, 253) at the
   limit d / (1 + n0 d/100), n0 the number of zeros (0.25 % lower for d = 0.05 and five zeros). In a
   porphyry table many phases are absent by type (calcite, chlorite, muscovite), so the
   log-ratios of those zeros dominate the variance and are set by the arbitrary detection
   limit. Hence standard scaling by default; ``clr`` is offered for tables without such
   structural zeros.
2. **PCA** (``n_components``: int, or a float = fraction of variance to keep, default 0.90).
   Each component is oriented so that its scores correlate positively with the mineralogical
   hardness index ``H_min = sum w_i H_i`` (MISSION eq. 1): PC1 > 0 is the hard side.
   Components are named by their dominant loadings (``component_names_``).
3. **Clustering** in PC space for every k in ``k_range`` (default 2..8): k-means (default) or a
   Gaussian mixture with a tied covariance. The number of types is chosen by ``criterion``:
   the mean silhouette (Rousseeuw 1987, J. Comput. Appl. Math. 20, 53; maximised) or the BIC
   of a tied-covariance Gaussian mixture (Schwarz 1978; minimised). Both are computed and
   reported in ``criterion_values_``; only the chosen one decides. ``n_types`` fixes k.
4. **Assignment of new samples.** The types are modelled as Gaussians in PC space with the
   pooled within-type covariance (as linear discriminant analysis); ``predict_proba`` gives the
   posterior of each type, the confidence is the largest posterior. A sample is *flagged* (not
   forced into a type) when its squared Mahalanobis distance to the nearest type exceeds the
   quantile ``outlier_quantile`` of the predictive Hotelling T2 distribution of that type (an F
   distribution, exact for Gaussian types with a pooled covariance estimated from n - k
   degrees of freedom; the large-sample chi-square with n_components d.o.f. is too tight
   for 47 samples: it flagged one training sample of the reference library), or when its
   squared residual off the PCA plane (SPE, Q statistic) exceeds the Box (1954) chi-square
   approximation of the training SPE at the same quantile (Nomikos & MacGregor 1995,
   Technometrics 37, 41), or when it contains minerals the typer never saw.
   ``predict`` returns -1 for flagged samples.

Only the ``<mineral>_wt_pct`` columns enter the PCA (MISSION: "PCA of the mineralogy
matrix"); texture columns are not used. A mineral column missing from a table passed to
``predict``/``assign`` counts as 0 wt%.

Types are numbered 0..k-1 by decreasing mean PC1 score (hardest first) and named after the
nearest reference ore A-D (``twin/ore/data/ores.toml``) projected into the same PC space
(``type_names_``), a letter used only once; a type with no unique nearest reference is
called ``T<i>``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from sklearn.base import BaseEstimator
from sklearn.cluster import KMeans
from sklearn.decomposition import PCA
from sklearn.metrics import silhouette_score
from sklearn.mixture import GaussianMixture
from sklearn.preprocessing import StandardScaler

from ..errors import TwinInputError, bad_value, close_matches
from .minerals import CLAY_MINERALS, SULFIDE_MINERALS, mineral_table
from .ores import reference_ores
from .mineralogy import SUM_TOLERANCE_WT_PCT, fractions_hint
from .samples import ID_COLUMN, WT_SUFFIX, from_mineralogies, mineral_columns, mineral_of

_TRANSFORMS = ("standard", "clr")
_METHODS = ("kmeans", "gmm")
_CRITERIA = ("silhouette", "bic")


class OreTyper(BaseEstimator):
    """Ore types from a sample table (columns ``<mineral>_wt_pct``); see the module docstring.

    Parameters
    ----------
    transform : {"standard", "clr"}
    n_components : int or float in (0, 1) (fraction of variance kept)
    k_range : (k_min, k_max), candidate numbers of types, inclusive
    n_types : int or None; fixes the number of types (skips the criterion)
    method : {"kmeans", "gmm"}
    criterion : {"silhouette", "bic"}
    outlier_quantile : float in (0.5, 1); quantile beyond which a sample is flagged
    detection_limit_wt_pct : float > 0; zero replacement for ``transform="clr"``
    random_state : int or None

    Fitted attributes
    -----------------
    feature_names_in_, minerals_, scaler_, pca_, n_components_, explained_variance_ratio_,
    loadings_ (DataFrame minerals x PCs, unit eigenvectors), component_names_,
    hardness_correlation_ (correlation of each PC's scores with H_min), criterion_values_
    ({"silhouette": {k: ..}, "bic": {k: ..}}), n_types_, labels_, scores_ (training PC
    scores), means_, covariance_, weights_, type_names_, d2_limits_ (per type), d2_limit_chi2_, spe_limit_.
    """

    def __init__(self, *, transform="standard", n_components=0.90, k_range=(2, 8), n_types=None,
                 method="kmeans", criterion="silhouette", outlier_quantile=0.999,
                 detection_limit_wt_pct=0.05, random_state=None):
        self.transform = transform
        self.n_components = n_components
        self.k_range = k_range
        self.n_types = n_types
        self.method = method
        self.criterion = criterion
        self.outlier_quantile = outlier_quantile
        self.detection_limit_wt_pct = detection_limit_wt_pct
        self.random_state = random_state

    # ------------------------------------------------------------------ validation helpers
    def _check_params(self, n_samples: int):
        for name, value, allowed in (("transform", self.transform, _TRANSFORMS),
                                     ("method", self.method, _METHODS),
                                     ("criterion", self.criterion, _CRITERIA)):
            if value not in allowed:
                raise bad_value("OreTyper", name, value, f"a str among {{{', '.join(map(repr, allowed))}}}")
        try:
            k_lo, k_hi = (int(k) for k in self.k_range)
        except (TypeError, ValueError):
            raise bad_value("OreTyper", "k_range", self.k_range, "a pair of integers (k_min, k_max)") from None
        if not 2 <= k_lo <= k_hi <= n_samples - 1:
            raise bad_value("OreTyper", "k_range", self.k_range,
                            f"a pair 2 <= k_min <= k_max <= n_samples - 1 = {n_samples - 1}")
        if self.n_types is not None and not (isinstance(self.n_types, (int, np.integer))
                                             and 1 <= self.n_types <= n_samples - 1):
            raise bad_value("OreTyper", "n_types", self.n_types, f"None or an int in [1, {n_samples - 1}]")
        nc = self.n_components
        if isinstance(nc, (bool, np.bool_)) or not (
                (isinstance(nc, (int, np.integer)) and nc >= 1)
                or (isinstance(nc, (float, np.floating)) and 0.0 < nc < 1.0)):
            raise bad_value("OreTyper", "n_components", nc,
                            "an int >= 1 or a float in (0, 1) (fraction of variance kept)")
        if not 0.5 < float(self.outlier_quantile) < 1.0:
            raise bad_value("OreTyper", "outlier_quantile", self.outlier_quantile, "a float in (0.5, 1)")
        if not float(self.detection_limit_wt_pct) > 0:
            raise bad_value("OreTyper", "detection_limit_wt_pct", self.detection_limit_wt_pct, "a float > 0")
        return k_lo, k_hi

    def _matrix(self, X, fitting: bool) -> tuple[np.ndarray, np.ndarray]:
        """wt% matrix in the fitted column order, and the wt% in minerals not seen in fit."""
        if not isinstance(X, pd.DataFrame):  # columns x0_wt_pct...: no hardness, types named at random
            raise bad_value("OreTyper", "X", f"a {type(X).__name__}", "a sample table (pandas DataFrame) with "
                            "'<mineral>_wt_pct' columns: its types are ordered by hardness and named after the "
                            "reference ores, both read from the minerals")
        cols = mineral_columns(X)
        if not cols:
            raise TwinInputError("OreTyper needs a sample table with '<mineral>_wt_pct' columns. "
                                 f"Got columns {list(X.columns)}.")
        table = mineral_table()
        unknown = [c for c in cols if c[: -len(WT_SUFFIX)] not in table]
        if unknown:  # a misspelt column had no hardness and moved the components' orientation
            m = unknown[0][: -len(WT_SUFFIX)]
            raise TwinInputError(f"OreTyper: column {unknown[0]!r} names no mineral of the table."
                                 f"{close_matches(m, table)}")
        total = X[cols].to_numpy(float).sum(axis=1)
        off = np.flatnonzero(np.abs(total - 100.0) > SUM_TOLERANCE_WT_PCT)
        if off.size:  # fractions, or a column missing, were typed with confidence 1
            raise TwinInputError(f"OreTyper: the wt% of {off.size} sample rows do not sum to 100 within "
                                 f"{SUM_TOLERANCE_WT_PCT} wt% (row {int(off[0])}: {total[off[0]]:.4g}"
                                 f"{fractions_hint(float(total[off[0]]))}); validate the table with "
                                 "twin.ore.samples.validate_samples")
        if fitting:
            self.feature_names_in_ = np.array(cols, dtype=object)
        names = list(self.feature_names_in_)
        M = np.column_stack([X[c].to_numpy(float) if c in X.columns else np.zeros(len(X)) for c in names])
        unseen = X[[c for c in cols if c not in names]].to_numpy(float).sum(axis=1) \
            if any(c not in names for c in cols) else np.zeros(len(X))
        if not np.all(np.isfinite(M)) or np.any(M < 0):
            raise TwinInputError("OreTyper: wt% values must be finite and >= 0 "
                                 "(validate the table with twin.ore.samples.validate_samples).")
        return M, unseen

    def _scaled(self, M: np.ndarray, fitting: bool) -> np.ndarray:
        if self.transform == "clr":
            Z = np.where(M > 0, M, float(self.detection_limit_wt_pct))
            L = np.log(Z)
            L = L - L.mean(axis=1, keepdims=True)
            if fitting:
                self.scaler_ = StandardScaler(with_std=False).fit(L)
            return self.scaler_.transform(L)
        if fitting:
            self.scaler_ = StandardScaler().fit(M)
        return self.scaler_.transform(M)

    # ------------------------------------------------------------------ fit
    def fit(self, X, y=None):
        """Fit scaling, PCA and the clustering; choose the number of types."""
        n = len(X)
        k_lo, k_hi = self._check_params(n)
        M, _ = self._matrix(X, fitting=True)
        distinct = len(np.unique(M, axis=0))
        if distinct <= k_lo:  # each type then holds copies of one composition: no spread to type new samples by
            raise TwinInputError(f"OreTyper: the {n} samples have {distinct} distinct composition"
                                 f"{'s' if distinct != 1 else ''}; typing them into at least {k_lo} types needs "
                                 "more (repeat assays of a sample are one sample).")
        self.minerals_ = [mineral_of(c) for c in self.feature_names_in_]
        Z = self._scaled(M, fitting=True)
        self.pca_ = PCA(n_components=self.n_components, svd_solver="full",
                        random_state=self.random_state).fit(Z)
        self.n_components_ = int(self.pca_.n_components_)
        # orient each PC so that its scores rise with the hardness index H_min
        h_min = self._hardness(M)
        raw = self.pca_.transform(Z)
        corr = np.array([_corr(raw[:, j], h_min) for j in range(self.n_components_)])
        signs = np.where(corr < 0, -1.0, 1.0)
        self.pca_.components_ = self.pca_.components_ * signs[:, None]
        self.hardness_correlation_ = corr * signs
        self.explained_variance_ratio_ = self.pca_.explained_variance_ratio_.copy()
        pcs = [f"PC{j + 1}" for j in range(self.n_components_)]
        self.loadings_ = pd.DataFrame(self.pca_.components_.T, index=self.minerals_, columns=pcs)
        self.component_names_ = {pc: _name_component(self.loadings_[pc]) for pc in pcs}
        S = self.pca_.transform(Z)
        self.scores_ = S

        self.criterion_values_ = {"silhouette": {}, "bic": {}}
        fits = {}
        for k in range(k_lo, k_hi + 1):
            labels, bic = self._cluster(S, k)
            fits[k] = labels
            self.criterion_values_["bic"][k] = bic
            self.criterion_values_["silhouette"][k] = (
                float(silhouette_score(S, labels)) if len(set(labels)) > 1 else math.nan)
        if self.n_types is not None:
            k = int(self.n_types)
            labels = fits[k] if k in fits else self._cluster(S, k)[0]
        else:
            vals = self.criterion_values_[self.criterion]
            k = (max(vals, key=lambda q: -np.inf if math.isnan(vals[q]) else vals[q])
                 if self.criterion == "silhouette" else min(vals, key=vals.get))
            labels = fits[k]
        self.n_types_ = k
        # number the types by decreasing mean PC1 (hardest first)
        order = np.argsort([-S[labels == c, 0].mean() for c in range(k)])
        relabel = np.empty(k, dtype=int)
        relabel[order] = np.arange(k)
        self.labels_ = relabel[labels]
        self._fit_type_model(S)
        self._fit_limits(Z, S)
        self.type_names_ = self._name_types()
        return self

    def _hardness(self, M: np.ndarray) -> np.ndarray:
        table = mineral_table()
        h = np.array([table[m].vickers_gpa if m in table else 0.0 for m in self.minerals_])
        tot = M.sum(axis=1)
        return M @ h / np.where(tot > 0, tot, 1.0)

    def _cluster(self, S: np.ndarray, k: int) -> tuple[np.ndarray, float]:
        gmm = GaussianMixture(k, covariance_type="tied", n_init=1, reg_covar=1e-6,
                              random_state=self.random_state).fit(S)
        bic = float(gmm.bic(S))
        if self.method == "gmm":
            return gmm.predict(S), bic
        km = KMeans(k, n_init=10, random_state=self.random_state).fit(S)
        return km.labels_, bic

    def _fit_type_model(self, S: np.ndarray):
        k, n, d = self.n_types_, len(S), S.shape[1]
        self.means_ = np.array([S[self.labels_ == c].mean(axis=0) for c in range(k)])
        resid = S - self.means_[self.labels_]
        dof = max(n - k, 1)
        cov = resid.T @ resid / dof
        if not np.trace(cov) > 0:  # every type's samples the same scores: no spread to type new samples by
            raise TwinInputError(f"OreTyper: each of the {k} types of the {n} samples holds copies of one "
                                 "composition: a type's spread, which new samples are typed against, is zero. "
                                 "Give samples that vary (repeat assays of a sample are one sample).")
        cov += 1e-9 * np.trace(cov) / d * np.eye(d)
        self.covariance_ = cov
        self._prec = np.linalg.inv(cov)
        self.weights_ = np.bincount(self.labels_, minlength=k) / n

    def _fit_limits(self, Z: np.ndarray, S: np.ndarray):
        q = float(self.outlier_quantile)
        p, k, n = self.n_components_, self.n_types_, len(S)
        nu = n - k  # degrees of freedom of the pooled covariance
        counts = np.bincount(self.labels_, minlength=k)
        if nu - p + 1 > 0:
            # predictive Hotelling T2 of a new observation of type c (Mardia, Kent & Bibby 1979,
            # Multivariate Analysis, 3.5): n_c/(n_c+1) d2 (nu-p+1)/(nu p) ~ F(p, nu-p+1)
            f = float(stats.f.ppf(q, p, nu - p + 1))
            self.d2_limits_ = (counts + 1) / counts * nu * p / (nu - p + 1) * f
        else:  # too few samples for the F form: large-sample chi-square
            self.d2_limits_ = np.full(k, float(stats.chi2.ppf(q, df=p)))
        self.d2_limit_chi2_ = float(stats.chi2.ppf(q, df=p))
        spe = self._spe(Z, S)
        mean, var = float(spe.mean()), float(spe.var(ddof=1))
        if mean <= 0 or var <= 0:  # all variance kept: no residual space
            self.spe_limit_ = math.inf
        else:
            g, h = var / (2 * mean), 2 * mean ** 2 / var
            self.spe_limit_ = float(g * stats.chi2.ppf(q, df=h))

    def _spe(self, Z, S):
        recon = S @ self.pca_.components_ + self.pca_.mean_
        return ((Z - recon) ** 2).sum(axis=1)

    def _name_types(self) -> list[str]:
        refs = reference_ores()
        table = from_mineralogies(refs.values(), ids=list(refs))
        Sref = self.transform_scores(table)
        d2 = np.array([[(m - s) @ self._prec @ (m - s) for s in Sref] for m in self.means_])
        names = [f"T{c}" for c in range(self.n_types_)]
        letters = list(refs)
        # greedy unique matching, closest pair first
        pairs = sorted((d2[c, r], c, r) for c in range(len(d2)) for r in range(len(letters)))
        used_c, used_r = set(), set()
        for _, c, r in pairs:
            if c not in used_c and r not in used_r:
                names[c] = letters[r]
                used_c.add(c)
                used_r.add(r)
        return names

    # ------------------------------------------------------------------ use
    def _check_fitted(self):
        if not hasattr(self, "means_"):
            raise TwinInputError("This OreTyper is not fitted yet; call fit(samples) first.")

    def transform_scores(self, X) -> np.ndarray:
        """PC scores of samples (n x n_components_)."""
        self._check_fitted()
        M, _ = self._matrix(X, fitting=False)
        return self.pca_.transform(self._scaled(M, fitting=False))

    def transform(self, X) -> np.ndarray:
        return self.transform_scores(X)

    def _assess(self, X):
        self._check_fitted()
        M, unseen = self._matrix(X, fitting=False)
        Z = self._scaled(M, fitting=False)
        S = self.pca_.transform(Z)
        diff = S[:, None, :] - self.means_[None, :, :]
        d2 = np.einsum("nkd,de,nke->nk", diff, self._prec, diff)
        logp = np.log(self.weights_)[None, :] - 0.5 * d2
        logp -= logp.max(axis=1, keepdims=True)
        post = np.exp(logp)
        post /= post.sum(axis=1, keepdims=True)
        spe = self._spe(Z, S)
        return S, d2, post, spe, unseen

    def predict_proba(self, X) -> np.ndarray:
        """Posterior probability of each type (rows sum to 1, also for flagged samples:
        check :meth:`assign` or :meth:`predict` for the flag)."""
        return self._assess(X)[2]

    def predict(self, X) -> np.ndarray:
        """Type number of each sample, -1 where the sample is flagged as far from every type."""
        return self.assign(X)["type"].to_numpy(int)

    def fit_predict(self, X, y=None) -> np.ndarray:
        return self.fit(X).labels_.copy()

    def assign(self, X) -> pd.DataFrame:
        """One row per sample: type (-1 if flagged), type_name, confidence (largest posterior),
        mahalanobis_d2 to the nearest type and its limit, spe and its limit, flagged, reason."""
        S, d2, post, spe, unseen = self._assess(X)
        ratio = d2 / self.d2_limits_[None, :]
        nearest = ratio.argmin(axis=1)
        d2min = d2[np.arange(len(d2)), nearest]
        lim = self.d2_limits_[nearest]
        reasons = []
        for i in range(len(S)):
            r = []
            if d2min[i] > lim[i]:
                r.append(f"Mahalanobis d2 {d2min[i]:.1f} > {lim[i]:.1f} of the nearest type "
                         f"{self.type_names_[nearest[i]]} (beyond every type's limit)")
            if spe[i] > self.spe_limit_:
                r.append(f"SPE {spe[i]:.2f} > {self.spe_limit_:.2f}")
            if unseen[i] > 0:
                r.append(f"{unseen[i]:.2f} wt% in minerals not seen in fit")
            reasons.append("; ".join(r))
        flagged = np.array([bool(r) for r in reasons])
        best = post.argmax(axis=1)
        out = pd.DataFrame({
            "type": np.where(flagged, -1, best),
            "type_name": [("unassigned" if f else self.type_names_[b]) for f, b in zip(flagged, best)],
            "nearest_type_name": [self.type_names_[b] for b in nearest],
            "confidence": post.max(axis=1),
            "mahalanobis_d2": d2min,
            "d2_limit": lim,
            "spe": spe,
            "spe_limit": self.spe_limit_,
            "flagged": flagged,
            "reason": reasons,
        })
        if isinstance(X, pd.DataFrame) and ID_COLUMN in X.columns:
            out.insert(0, ID_COLUMN, X[ID_COLUMN].to_numpy())
        return out

    def report(self) -> dict:
        """Numbers for a report: explained variance, component names, criterion values, k."""
        self._check_fitted()
        return {
            "transform": self.transform,
            "n_components": self.n_components_,
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio_],
            "pc1_pc2_explained": float(self.explained_variance_ratio_[:2].sum()),
            "component_names": dict(self.component_names_),
            "hardness_correlation": [float(v) for v in self.hardness_correlation_],
            "criterion": self.criterion,
            "criterion_values": {c: {int(k): float(v) for k, v in d.items()}
                                 for c, d in self.criterion_values_.items()},
            "n_types": int(self.n_types_),
            "type_names": list(self.type_names_),
            "type_sizes": np.bincount(self.labels_, minlength=self.n_types_).tolist(),
        }


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    if np.std(a) == 0 or np.std(b) == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def _name_component(loadings: pd.Series, top: int = 3, rel: float = 0.5) -> str:
    """'quartz+k_feldspar vs illite+kaolinite': the largest positive and negative loadings
    (at most ``top`` per side, each at least ``rel`` x the largest |loading|)."""
    big = float(loadings.abs().max())
    pos = loadings[loadings >= rel * big].sort_values(ascending=False).index[:top]
    neg = loadings[loadings <= -rel * big].sort_values().index[:top]
    left = "+".join(pos) or "-"
    right = "+".join(neg) or "-"
    return f"{left} vs {right}"


# ---------------------------------------------------------------------- plots
def ternary_coordinates(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quartz, clay (kaolinite + illite), sulfide (pyrite + chalcopyrite + bornite) fractions
    normalised to their sum, and the (x, y) of the ternary plot (quartz at the left corner,
    clay at the right, sulfide at the top)."""
    def col(m):
        c = m + WT_SUFFIX
        return frame[c].to_numpy(float) if c in frame.columns else np.zeros(len(frame))
    q = col("quartz")
    c = sum(col(m) for m in CLAY_MINERALS)
    s = sum(col(m) for m in SULFIDE_MINERALS)
    tot = q + c + s
    tot = np.where(tot > 0, tot, 1.0)
    fr = np.column_stack([q, c, s]) / tot[:, None]
    x = fr[:, 1] + 0.5 * fr[:, 2]
    y = math.sqrt(3) / 2 * fr[:, 2]
    return fr, x, y


def plot_ternary(frame: pd.DataFrame, labels, path: str | Path, names=None, title=None) -> Path:
    """Ternary quartz-clay-sulfide diagram coloured by type, written as PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = np.asarray(labels)
    _, x, y = ternary_coordinates(frame)
    fig, ax = plt.subplots(figsize=(6, 5.4))
    h = math.sqrt(3) / 2
    ax.plot([0, 1, 0.5, 0], [0, 0, h, 0], color="k", lw=1)
    for f in (0.2, 0.4, 0.6, 0.8):  # grid lines of constant sulfide fraction
        ax.plot([f / 2, 1 - f / 2], [f * h, f * h], color="0.85", lw=0.6)
    ax.text(-0.03, -0.04, "quartz", ha="right")
    ax.text(1.03, -0.04, "clay", ha="left")
    ax.text(0.5, h + 0.03, "sulfide", ha="center")
    for lab in sorted(set(labels.tolist())):
        sel = labels == lab
        name = names[lab] if names is not None and lab >= 0 else ("flagged" if lab == -1 else str(lab))
        ax.scatter(x[sel], y[sel], s=28, label=f"{name} (n={sel.sum()})",
                   marker="x" if lab == -1 else "o")
    ax.set_aspect("equal")
    ax.axis("off")
    ax.legend(loc="upper right", fontsize=8, frameon=False)
    ax.set_title(title or "Quartz-clay-sulfide (normalised to their sum)", fontsize=10)
    path = Path(path)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_scores(typer: OreTyper, frame: pd.DataFrame, path: str | Path, labels=None) -> Path:
    """PC1-PC2 score plot coloured by type, with the loadings as arrows, written as PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    S = typer.transform_scores(frame)
    labels = typer.predict(frame) if labels is None else np.asarray(labels)
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    for lab in sorted(set(labels.tolist())):
        sel = labels == lab
        name = typer.type_names_[lab] if lab >= 0 else "flagged"
        ax.scatter(S[sel, 0], S[sel, 1] if S.shape[1] > 1 else np.zeros(sel.sum()), s=28,
                   label=f"{name} (n={sel.sum()})", marker="x" if lab == -1 else "o")
    if S.shape[1] > 1:
        scale = 0.8 * np.abs(S[:, :2]).max()
        L = typer.loadings_.iloc[:, :2].to_numpy()
        for m, (a, b) in zip(typer.minerals_, L):
            ax.annotate("", xy=(a * scale, b * scale), xytext=(0, 0),
                        arrowprops=dict(arrowstyle="->", color="0.5", lw=0.7))
            ax.text(a * scale * 1.05, b * scale * 1.05, m, fontsize=7, color="0.3")
    ev = typer.explained_variance_ratio_
    ax.set_xlabel(f"PC1 {100 * ev[0]:.1f} %: {typer.component_names_['PC1']}", fontsize=8)
    if len(ev) > 1:
        ax.set_ylabel(f"PC2 {100 * ev[1]:.1f} %: {typer.component_names_['PC2']}", fontsize=8)
    ax.axhline(0, color="0.9", lw=0.6)
    ax.axvline(0, color="0.9", lw=0.6)
    ax.legend(fontsize=8, frameon=False)
    path = Path(path)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


# ---------------------------------------------------------------------- command line
def main(argv=None) -> int:
    """``python -m twin.ore.oretyping [--samples FILE] --out DIR``: fit the ore typing on a sample
    table (default: the shipped synthetic library), write ``oretyping.json`` (explained
    variance, component names, criterion values, k), ``assignments.csv``, ``loadings.csv``,
    ``ternary.png`` and ``scores.png``."""
    import argparse

    from ..atomic import json_text
    from .sample_library import load_reference_samples
    from .samples import read_samples

    ap = argparse.ArgumentParser(prog="python -m twin.ore.oretyping", description=main.__doc__.splitlines()[0])
    ap.add_argument("--samples", help="sample table (CSV or Parquet); default: shipped library")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--criterion", default="silhouette", choices=_CRITERIA)
    ap.add_argument("--transform", default="standard", choices=_TRANSFORMS)
    ap.add_argument("--seed", type=int, default=0, help="random_state of the clustering")
    args = ap.parse_args(argv)
    try:  # bad input is said in a line with exit 2, as grindtwin's commands do, before anything is written
        frame = read_samples(args.samples) if args.samples else load_reference_samples()
        typer = OreTyper(criterion=args.criterion, transform=args.transform, random_state=args.seed).fit(frame)
    except TwinInputError as exc:
        sys.stderr.write(f"{ap.prog}: error: {exc}\n")
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rep = typer.report()
    (out / "oretyping.json").write_text(json_text(rep, indent=2), encoding="utf-8")  # a silhouette of one type: null
    typer.assign(frame).to_csv(out / "assignments.csv", index=False)
    typer.loadings_.to_csv(out / "loadings.csv", index_label="mineral")
    plot_ternary(frame, typer.labels_, out / "ternary.png", names=typer.type_names_)
    plot_scores(typer, frame, out / "scores.png")
    ev = rep["explained_variance_ratio"]
    print(f"{len(frame)} samples -> {rep['n_types']} types {rep['type_names']} by {rep['criterion']}; "
          f"PC1 {100 * ev[0]:.1f} % ({rep['component_names']['PC1']}), "
          f"PC2 {100 * ev[1]:.1f} % ({rep['component_names']['PC2']}); written to {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
