"""The fitted surrogate as plain arrays: its prediction and domain check in numpy alone, and a
``.npz`` file that holds them (``twin/surrogate/data/surrogate.npz``, beside the joblib).

The fitted scikit-learn pipeline (:class:`twin.surrogate.model.Surrogate`) is compiled into
these arrays at fit time; both the estimator and the command line predict through the functions
here, so there is one implementation. Loading the ``.npz`` imports neither scikit-learn nor
CasADi: a steady-state answer from the shipped surrogate costs a fraction of a second from a
cold start. ``python -m twin.surrogate --compile`` writes the file from the shipped joblib; a
test checks it is that joblib's and was made from the current calibration.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import TwinError, TwinInputError

TARGETS = ("p80_um", "specific_energy_kwh_t", "load_frac")
#: A PCA score may leave the trained [min, max] by this share of the trained range.
SCORE_MARGIN = 0.10
#: A mineralogy's PCA residual may reach this multiple of the largest training residual, and at
#: least Q_FLOOR (with all PCs kept the training residual is round-off).
Q_LIMIT_FACTOR = 1.5
Q_FLOOR = 1e-8
COMPILED_FORMAT_VERSION = 1
#: The arrays of the compiled pipeline (keys of ``Surrogate._c``).
ARRAY_KEYS = ("m_idx", "m_mu", "m_sd", "pca_mu", "pca_W", "log_idx", "log_mu", "log_sd", "lin_idx",
              "lin_mu", "lin_sd", "pairs", "x_mean", "coef", "intercept", "lo", "hi")


def scores_and_q(c: dict, A: np.ndarray):
    """PCA scores of the standardised mineral wt% and the PCA residual Q (squared norm)."""
    z = (A[:, c["m_idx"]] - c["m_mu"]) / c["m_sd"] - c["pca_mu"]
    s = z @ c["pca_W"]
    q = ((z - s @ c["pca_W"].T) ** 2).sum(axis=1)
    return s, q


def predict_arrays(c: dict, A: np.ndarray, sq=None) -> np.ndarray:
    """KPIs (n, 3) in units, order :data:`TARGETS`: scaled scores, log and linear inputs, their
    degree-2 products (``pairs``, index -1 a column of ones), PLS coefficients, exp."""
    s, _ = sq if sq is not None else scores_and_q(c, A)
    lg = (np.log(A[:, c["log_idx"]]) - c["log_mu"]) / c["log_sd"]
    ln = (A[:, c["lin_idx"]] - c["lin_mu"]) / c["lin_sd"]
    Z = np.hstack([s, lg, ln, np.ones((len(A), 1))])  # last column: 1, for linear terms
    F = Z[:, c["pairs"][0]] * Z[:, c["pairs"][1]]
    return np.exp((F - c["x_mean"]) @ c["coef"] + c["intercept"])


def domain_problems(c: dict, names, score_range: np.ndarray, q_limit: float, A: np.ndarray,
                    max_problems: int = 20, sq=None) -> list[str]:
    """Why rows of A lie outside the training domain: a raw input outside its trained box, a PCA
    score outside its trained range (+- SCORE_MARGIN), a PCA residual above ``q_limit``."""
    s, q = sq if sq is not None else scores_and_q(c, A)
    lo, hi = score_range[:, 0], score_range[:, 1]
    pad = SCORE_MARGIN * (hi - lo)
    bad_box = (A < c["lo"]) | (A > c["hi"]) | ~np.isfinite(A)
    bad_s = (s < lo - pad) | (s > hi + pad)
    bad_q = q > q_limit
    out = []
    for i in np.flatnonzero(bad_box.any(axis=1) | bad_s.any(axis=1) | bad_q):
        for j in np.flatnonzero(bad_box[i]):
            out.append(f"row {i}: the '{names[j]}' input of Surrogate must be in the trained "
                       f"range [{c['lo'][j]:.6g}, {c['hi'][j]:.6g}]. Got {A[i, j]:.6g}.")
        for j in np.flatnonzero(bad_s[i]):
            out.append(f"row {i}: the mineralogy's PCA score {j + 1} of Surrogate must be in the trained "
                       f"range [{lo[j]:.4g}, {hi[j]:.4g}] (+-{SCORE_MARGIN:.0%}). Got {s[i, j]:.4g}: "
                       "a mineral combination outside the training design.")
        if bad_q[i]:
            out.append(f"row {i}: the mineralogy's PCA residual (Q) of Surrogate must be <= "
                       f"{q_limit:.4g} ({Q_LIMIT_FACTOR} x the largest in training, at least {Q_FLOOR:g}). "
                       f"Got {q[i]:.4g}: a mineral combination unlike the training mineralogies.")
        if len(out) >= max_problems:
            break
    return out


def checked_predict(c: dict, names, score_range, q_limit, A: np.ndarray, check_domain: bool = True):
    """:func:`predict_arrays`, after refusing inputs outside the domain (TwinInputError)."""
    sq = scores_and_q(c, A)
    if check_domain:
        problems = domain_problems(c, names, score_range, q_limit, A, 5, sq)
        if problems:
            raise TwinInputError("Input outside the surrogate's training domain (the surrogate does not "
                                 "extrapolate; use the twin): " + " | ".join(problems))
    return predict_arrays(c, A, sq)


@dataclass
class CompiledSurrogate:
    """A fitted surrogate as arrays: ``feature_names`` (the input columns, in order), ``arrays``
    (the compiled pipeline), ``score_range`` and ``q_limit`` (the domain), ``metadata`` (what it
    was made from)."""

    feature_names: tuple
    arrays: dict
    score_range: np.ndarray
    q_limit: float
    metadata: dict = field(default_factory=dict)

    def predict(self, A, check_domain: bool = True) -> np.ndarray:
        """KPIs (n, 3), order :data:`TARGETS`, of input rows in the order of ``feature_names``."""
        A = np.atleast_2d(np.asarray(A, float))
        if A.shape[1] != len(self.feature_names):
            raise TwinInputError(f"The 'X' of CompiledSurrogate must have {len(self.feature_names)} columns "
                                 f"in the order of feature_names. Got shape {A.shape}.")
        return checked_predict(self.arrays, self.feature_names, self.score_range, self.q_limit, A, check_domain)

    def save(self, path: str | Path) -> Path:
        """Write the arrays and the metadata (JSON) to one ``.npz`` (via a temporary file)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".partial.npz")
        meta = dict(self.metadata, compiled_format_version=COMPILED_FORMAT_VERSION)
        np.savez_compressed(tmp, **{f"a_{k}": np.asarray(self.arrays[k]) for k in ARRAY_KEYS},
                            feature_names=np.array(self.feature_names, dtype=str),
                            score_range=self.score_range, q_limit=np.array(self.q_limit),
                            metadata=np.array(json.dumps(meta, sort_keys=True)))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> "CompiledSurrogate":
        """Read a file written by :meth:`save`; TwinError for another format version."""
        path = Path(path)
        if not path.is_file():
            raise TwinError(f"No compiled surrogate {path}: run `python -m twin.surrogate --compile`.")
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["metadata"]))
            if meta.get("compiled_format_version") != COMPILED_FORMAT_VERSION:
                raise TwinError(f"Compiled surrogate {path} has format version "
                                f"{meta.get('compiled_format_version')!r}; this code reads "
                                f"{COMPILED_FORMAT_VERSION}. Regenerate it: `python -m twin.surrogate --compile`.")
            return cls(tuple(str(n) for n in z["feature_names"]), {k: z[f"a_{k}"] for k in ARRAY_KEYS},
                       z["score_range"], float(z["q_limit"]), meta)


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
