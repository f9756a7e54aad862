"""The surrogate: PCA of the mineralogy + PLS regression (MISSION.md eq. 8, ``Y = X B + E``) to the
twin's steady-state KPIs, a scikit-learn estimator that refuses inputs outside its training
domain. What it predicts, its settings and their reasons: docs/surrogate.md."""

from __future__ import annotations

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.compose import ColumnTransformer
from sklearn.cross_decomposition import PLSRegression
from sklearn.decomposition import PCA
from sklearn.metrics import r2_score
from sklearn.model_selection import GroupKFold, GroupShuffleSplit
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import FunctionTransformer, PolynomialFeatures, StandardScaler

from ..errors import TwinError, TwinInputError, bad_value
from ..ore.mineralogy import TEXTURE_COLUMNS, WT_SUFFIX
from .compiled import (Q_FLOOR, Q_LIMIT_FACTOR, TARGETS, CompiledSurrogate, as_rows, checked_predict,
                       domain_problems, plain, score_and_q)
from .inputs import CONDITION_COLUMNS, input_columns, mineral_names

#: Shipped hyper-parameters, chosen by grouped 5-fold CV and held-out error on the shipped table
#: (the grid is in benchmarks/results/twin_surrogate.md).
DEFAULT_PARAMS = {"n_components": 80, "n_pca": 10, "degree": 2}
#: A raw input may leave its trained [min, max] by this share of the trained range.
RANGE_MARGIN = 0.05
#: A mineral whose smallest trained content is below this [wt%] may also be absent (range from 0).
TRACE_WT_PCT = 1.0


def _product_pairs(powers: np.ndarray) -> np.ndarray:
    """PolynomialFeatures (degree <= 2) as index pairs (a, b): feature = Z[a] * Z[b], where
    index -1 is a column of ones appended to Z."""
    pairs = np.full((2, len(powers)), -1, dtype=int)
    for k, p in enumerate(powers):
        idx = [i for i, e in enumerate(p) for _ in range(int(e))]
        if not 1 <= len(idx) <= 2:
            raise TwinError(f"Polynomial term {p.tolist()} is not of degree 1 or 2.")
        pairs[: len(idx), k] = idx
    return pairs


class Surrogate(RegressorMixin, BaseEstimator):
    """PCA of the mineralogy + PLS regression (eq. 8) to the steady-state KPIs.

    Parameters
    ----------
    n_components : int, number of PLS latent variables (<= number of expanded features).
    n_pca : int, number of principal components kept of the standardised mineral wt%.
    degree : int in {1, 2}, degree of the polynomial expansion of [PC scores, texture,
        conditions] before the PLS (1 = plain linear eq. 8).
    random_state : int, seed of the PCA's randomised solver when it is used (the 'full'
        solver is chosen for these small matrices, so results do not depend on it).

    ``X``: a DataFrame with the columns of :func:`feature_frame`; ``y``: a DataFrame with the
    columns of :data:`TARGETS` (or an array in that order). ``predict`` returns an array
    (n, 3) in KPI units in the order of :data:`TARGETS`, after checking the training domain.
    """

    def __init__(self, n_components: int = DEFAULT_PARAMS["n_components"], n_pca: int = DEFAULT_PARAMS["n_pca"],
                 degree: int = DEFAULT_PARAMS["degree"], random_state: int = 0):
        self.n_components = n_components
        self.n_pca = n_pca
        self.degree = degree
        self.random_state = random_state

    # -- fitting
    def _check_params(self, n_minerals: int, n_samples: int):
        if not isinstance(self.n_pca, (int, np.integer)) or not 1 <= self.n_pca <= n_minerals:
            raise bad_value("Surrogate", "n_pca", self.n_pca, f"an integer in [1, {n_minerals}]")
        if self.degree not in (1, 2):
            raise bad_value("Surrogate", "degree", self.degree, "1 or 2")
        n_lin = self.n_pca + len(TEXTURE_COLUMNS) + len(CONDITION_COLUMNS)
        n_feat = n_lin if self.degree == 1 else n_lin + n_lin * (n_lin + 1) // 2
        hi = min(n_feat, n_samples - 1)
        if not isinstance(self.n_components, (int, np.integer)) or not 1 <= self.n_components <= hi:
            raise bad_value("Surrogate", "n_components", self.n_components, f"an integer in [1, {hi}]")

    def _pipeline(self, mineral_cols) -> Pipeline:
        pre = ColumnTransformer([
            ("minerals", Pipeline([("scale", StandardScaler()),
                                   ("pca", PCA(self.n_pca, svd_solver="full", random_state=self.random_state))]),
             list(mineral_cols)),
            ("log", Pipeline([("log", FunctionTransformer(np.log)), ("scale", StandardScaler())]),
             ["mean_grain_um", "feed_tph"]),
            ("lin", StandardScaler(), ["uniformity", "association_entropy", "speed_frac_critical"]),
        ], verbose_feature_names_out=False)
        return Pipeline([("pre", pre), ("poly", PolynomialFeatures(self.degree, include_bias=False)),
                         ("pls", PLSRegression(self.n_components, scale=True))])

    def fit(self, X, y):
        X = self._as_frame(X)
        Y = self._targets(y, len(X))
        if len(X) < 3:
            raise bad_value("Surrogate.fit", "X", f"{len(X)} rows", "at least 3 rows")
        minerals = [m for m in mineral_names() if X[m + WT_SUFFIX].std() > 0]
        self._check_params(len(minerals), len(X))
        self.minerals_ = minerals
        self.feature_names_in_ = np.array(input_columns(), dtype=object)
        self.n_features_in_ = len(self.feature_names_in_)
        self.pipeline_ = self._pipeline([m + WT_SUFFIX for m in minerals])
        self.pipeline_.fit(X, np.log(Y))
        pls = self.pipeline_.named_steps["pls"]
        for big in ("_x_scores", "_y_scores", "x_scores_", "y_scores_"):  # training-set scores: not
            pls.__dict__.pop(big, None)  # needed to predict; 2.6 MB in the saved file
        self.input_range_ = {}
        for c in self.feature_names_in_:  # (trained range of each raw input, see RANGE_MARGIN)
            lo, hi = float(X[c].min()), float(X[c].max())
            pad = RANGE_MARGIN * (hi - lo)
            lo = 0.0 if c.endswith(WT_SUFFIX) and lo < TRACE_WT_PCT else max(lo - pad, 0.0)
            self.input_range_[c] = (lo, hi + pad)
        self._compile()
        scores, q = self._scores_and_q(X[list(self.feature_names_in_)].to_numpy(float))
        self.score_range_ = np.stack([scores.min(axis=0), scores.max(axis=0)], axis=1)
        self.q_limit_ = max(float(Q_LIMIT_FACTOR * q.max()), Q_FLOOR)
        return self

    def _targets(self, y, n) -> np.ndarray:
        Y = y[list(TARGETS)].to_numpy(float) if isinstance(y, pd.DataFrame) else np.asarray(y, float)
        if Y.shape != (n, len(TARGETS)):
            raise bad_value("Surrogate.fit", "y", f"shape {Y.shape}", f"shape ({n}, {len(TARGETS)}) in the order {TARGETS}")
        if not np.all(np.isfinite(Y)) or np.any(Y <= 0):
            raise bad_value("Surrogate.fit", "y", "non-positive or non-finite values", "finite positive KPIs")
        return Y

    @staticmethod
    def _as_frame(X) -> pd.DataFrame:
        if not isinstance(X, pd.DataFrame):
            raise TwinInputError("The 'X' of Surrogate must be a DataFrame with the columns of "
                                 "twin.surrogate.feature_frame (mineral wt%, texture, feed_tph, speed_frac_critical).")
        missing = [c for c in input_columns() if c not in X.columns]
        if missing:
            X = X.copy()
            for c in missing:
                if not c.endswith(WT_SUFFIX):
                    raise TwinInputError(f"The 'X' of Surrogate lacks the column {c!r}.")
                X[c] = 0.0  # a missing mineral column means 0 wt% (as in sample tables)
        return X

    def _as_array(self, X) -> np.ndarray:
        """X (DataFrame, or an array with the columns of ``feature_names_in_``) -> float array."""
        if isinstance(X, pd.DataFrame):
            return self._as_frame(X)[list(self.feature_names_in_)].to_numpy(float)
        A = np.asarray(X, float)
        if A.ndim != 2 or A.shape[1] != self.n_features_in_:
            raise TwinInputError(f"The 'X' of Surrogate must be a DataFrame or an array of shape (n, "
                                 f"{self.n_features_in_}) in the order of feature_names_in_. Got shape {A.shape}.")
        return A

    # -- the compiled (plain-number) form of the fitted pipeline, used by predict
    def _compile(self):
        pre = self.pipeline_.named_steps["pre"]
        mpipe = pre.named_transformers_["minerals"]
        sc, pca = mpipe.named_steps["scale"], mpipe.named_steps["pca"]
        lg = pre.named_transformers_["log"].named_steps["scale"]
        ln = pre.named_transformers_["lin"]
        pls = self.pipeline_.named_steps["pls"]
        idx = {c: i for i, c in enumerate(self.feature_names_in_)}
        self._c = plain({
            "m_idx": [idx[m + WT_SUFFIX] for m in self.minerals_],
            "m_mu": sc.mean_, "m_sd": sc.scale_, "pca_mu": pca.mean_, "pca_W": pca.components_.T,
            "log_idx": [idx["mean_grain_um"], idx["feed_tph"]], "log_mu": lg.mean_, "log_sd": lg.scale_,
            "lin_idx": [idx["uniformity"], idx["association_entropy"], idx["speed_frac_critical"]],
            "lin_mu": ln.mean_, "lin_sd": ln.scale_,
            "pairs": _product_pairs(self.pipeline_.named_steps["poly"].powers_),
            "x_mean": pls._x_mean, "coef": pls.coef_.T, "intercept": pls.intercept_,
            "lo": [r[0] for r in self.input_range_.values()],
            "hi": [r[1] for r in self.input_range_.values()],
        })

    def _scores_and_q(self, A: np.ndarray):
        """PCA scores (n, n_pca) and residuals (n,) of rows A, row by row (:func:`score_and_q`)."""
        sq = [score_and_q(self._c, row) for row in as_rows(A)]
        return np.array([s for s, _ in sq]), np.array([q for _, q in sq])

    def compiled(self, metadata: dict | None = None) -> CompiledSurrogate:
        """The fitted surrogate as plain numbers (:mod:`twin.surrogate.compiled`): Python alone predicts."""
        self._check_fitted()
        return CompiledSurrogate(tuple(self.feature_names_in_), dict(self._c), self.score_range_, self.q_limit_,
                                 dict(metadata if metadata is not None else getattr(self, "metadata_", {})))

    def _check_fitted(self):
        if not hasattr(self, "pipeline_"):
            raise TwinError("This Surrogate is not fitted yet: call fit(X, y) or load a saved one.")

    def domain_problems(self, X, max_problems: int = 20) -> list[str]:
        """Why rows of X lie outside the training domain (empty list: all inside)."""
        self._check_fitted()
        A = self._as_array(X)
        return self._domain(A, max_problems)

    def _domain(self, A: np.ndarray, max_problems: int = 20) -> list[str]:
        return domain_problems(self._c, self.feature_names_in_, self.score_range_, self.q_limit_, A, max_problems)

    def predict(self, X, check_domain: bool = True) -> np.ndarray:
        """KPIs (n, 3) in units, order :data:`TARGETS`. Raises TwinInputError for inputs
        outside the training domain unless ``check_domain=False``."""
        self._check_fitted()
        return self._predict_array(self._as_array(X), check_domain)

    def _predict_array(self, A: np.ndarray, check_domain: bool = True) -> np.ndarray:
        return np.array(checked_predict(self._c, self.feature_names_in_, self.score_range_, self.q_limit_, A,
                                        check_domain), float).reshape(-1, len(TARGETS))

    def predict_pipeline(self, X) -> np.ndarray:
        """The same prediction through the scikit-learn Pipeline (no domain check); the
        compiled :meth:`predict` is tested equal to it."""
        self._check_fitted()
        return np.exp(self.pipeline_.predict(self._as_frame(X)))

    def r2_per_kpi(self, X, y) -> dict:
        """R2 in KPI units per target."""
        Y = self._targets(y, len(X))
        P = self.predict(X, check_domain=False)
        return {t: float(r2_score(Y[:, i], P[:, i])) for i, t in enumerate(TARGETS)}

    def score(self, X, y, sample_weight=None) -> float:
        """Mean R2 over the KPIs, in KPI units."""
        return float(np.mean(list(self.r2_per_kpi(X, y).values())))


def split_xy(table: pd.DataFrame):
    """(X, Y, groups) of a training table; groups = mineralogy ids (a mineralogy's points
    never sit on both sides of a split)."""
    X = pd.DataFrame(table[input_columns()].to_numpy(float), columns=input_columns())
    Y = pd.DataFrame(table[list(TARGETS)].to_numpy(float), columns=list(TARGETS))
    return X, Y, table["mineralogy_id"].to_numpy()  # fresh frames: no attrs (pandas deep-copies them)


def cross_validate(table: pd.DataFrame, n_splits: int = 5, **params) -> dict:
    """Grouped k-fold CV (by mineralogy): R2 per KPI of the pooled out-of-fold predictions."""
    X, Y, g = split_xy(table)
    P = np.zeros(Y.shape)
    for tr, te in GroupKFold(n_splits).split(X, Y, g):
        P[te] = Surrogate(**params).fit(X.iloc[tr], Y.iloc[tr]).predict(X.iloc[te], check_domain=False)
    Yv = Y.to_numpy(float)
    return {t: float(r2_score(Yv[:, i], P[:, i])) for i, t in enumerate(TARGETS)}


def held_out_split(table: pd.DataFrame, test_size: float = 0.2, seed: int = 0):
    """(train, test) tables split by mineralogy."""
    X, Y, g = split_xy(table)
    tr, te = next(GroupShuffleSplit(1, test_size=test_size, random_state=seed).split(X, Y, g))
    return table.iloc[tr], table.iloc[te]
