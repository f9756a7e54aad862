"""The fitted surrogate as plain numbers: its prediction and domain check in pure Python, and a
JSON file that holds them (``twin/surrogate/data/surrogate.json``, beside the joblib).

The fitted scikit-learn pipeline (:class:`twin.surrogate.model.Surrogate`) is compiled into
these numbers at fit time; the fitted surrogate and the command line predict through the
functions here, row by row, so there is one implementation. Reading the file imports neither
numpy, scikit-learn nor CasADi: the command line's steady-state answer from the shipped
surrogate starts as fast as Python does (``benchmarks/cli_startup.py``).
``python -m twin.surrogate --compile`` writes the file from the shipped joblib; a test checks
it is that joblib's and was made from the current calibration.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from ..atomic import write_text_atomically
from ..errors import TwinError, TwinInputError

TARGETS = ("p80_um", "specific_energy_kwh_t", "load_frac")
#: A PCA score may leave the trained [min, max] by this share of the trained range.
SCORE_MARGIN = 0.10
#: A mineralogy's PCA residual may reach this multiple of the largest training residual, and at
#: least Q_FLOOR (with all PCs kept the training residual is round-off).
Q_LIMIT_FACTOR = 1.5
Q_FLOOR = 1e-8
#: 2: JSON of plain numbers (1 was a numpy .npz).
COMPILED_FORMAT_VERSION = 2
#: The numbers of the compiled pipeline: index lists, vectors, and the matrices ``pca_W``
#: (minerals x PCs), ``pairs`` (2 x features) and ``coef`` (features x targets) as row lists.
ARRAY_KEYS = ("m_idx", "m_mu", "m_sd", "pca_mu", "pca_W", "log_idx", "log_mu", "log_sd", "lin_idx",
              "lin_mu", "lin_sd", "pairs", "x_mean", "coef", "intercept", "lo", "hi")


def plain(c: dict) -> dict:
    """The compiled numbers as Python lists of floats and ints (from numpy arrays or lists)."""
    return {k: (c[k].tolist() if hasattr(c[k], "tolist") else list(c[k])) for k in ARRAY_KEYS}


def as_rows(A) -> list[list[float]]:
    """Input rows as lists of floats, from a 2-D array, a sequence of rows, or one row."""
    rows = A.tolist() if hasattr(A, "tolist") else list(A)
    if rows and not hasattr(rows[0], "__len__"):
        rows = [rows]
    return [[float(v) for v in r] for r in rows]


def score_and_q(c: dict, row) -> tuple[list[float], float]:
    """PCA scores of one row's standardised mineral wt% and its PCA residual Q (squared norm)."""
    z = [(row[i] - mu) / sd - pm for i, mu, sd, pm in zip(c["m_idx"], c["m_mu"], c["m_sd"], c["pca_mu"])]
    W = c["pca_W"]
    s = [math.fsum(zk * wk[j] for zk, wk in zip(z, W)) for j in range(len(W[0]))]
    q = math.fsum((zk - math.fsum(sj * wj for sj, wj in zip(s, wk))) ** 2 for zk, wk in zip(z, W))
    return s, q


def _log(x: float) -> float:
    """ln x, NaN for x <= 0 (a row outside the domain predicts NaN when it is not checked)."""
    return math.log(x) if x > 0 else math.nan


def predict_row(c: dict, row, s=None) -> list[float]:
    """One row's KPIs in units, order :data:`TARGETS`: scaled scores, log and linear inputs, their
    degree-2 products (``pairs``, index -1 the constant 1), PLS coefficients, exp."""
    s = score_and_q(c, row)[0] if s is None else s
    lg = [(_log(row[i]) - mu) / sd for i, mu, sd in zip(c["log_idx"], c["log_mu"], c["log_sd"])]
    ln = [(row[i] - mu) / sd for i, mu, sd in zip(c["lin_idx"], c["lin_mu"], c["lin_sd"])]
    Z = s + lg + ln + [1.0]  # last: 1, so that pairs with it are the linear terms
    F = [Z[a] * Z[b] - xm for a, b, xm in zip(c["pairs"][0], c["pairs"][1], c["x_mean"])]
    out = []
    for t, b in enumerate(c["intercept"]):
        y = math.fsum(f * ck[t] for f, ck in zip(F, c["coef"])) + b
        # 709: the largest exponent of a double (overflow is inf); NaN stays NaN, as numpy's exp
        out.append(math.inf if y > 709.0 else math.exp(y))
    return out


def row_problems(c: dict, names, score_range, q_limit: float, i: int, row, s, q) -> list[str]:
    """Why row ``i`` lies outside the training domain: a raw input outside its trained box, a PCA
    score outside its trained range (+- SCORE_MARGIN), a PCA residual above ``q_limit``."""
    out = []
    for j, (v, lo, hi) in enumerate(zip(row, c["lo"], c["hi"])):
        if not (lo <= v <= hi):
            out.append(f"row {i}: the '{names[j]}' input of Surrogate must be in the trained "
                       f"range [{lo:.6g}, {hi:.6g}]. Got {v:.6g}.")
    for j, (sj, (lo, hi)) in enumerate(zip(s, score_range)):
        pad = SCORE_MARGIN * (hi - lo)
        if not (lo - pad <= sj <= hi + pad):
            out.append(f"row {i}: the mineralogy's PCA score {j + 1} of Surrogate must be in the trained "
                       f"range [{lo:.4g}, {hi:.4g}] (+-{SCORE_MARGIN:.0%}). Got {sj:.4g}: "
                       "a mineral combination outside the training design.")
    if not q <= q_limit:
        out.append(f"row {i}: the mineralogy's PCA residual (Q) of Surrogate must be <= "
                   f"{q_limit:.4g} ({Q_LIMIT_FACTOR} x the largest in training, at least {Q_FLOOR:g}). "
                   f"Got {q:.4g}: a mineral combination unlike the training mineralogies.")
    return out


def domain_problems(c: dict, names, score_range, q_limit: float, A, max_problems: int = 20) -> list[str]:
    """Why rows of A lie outside the training domain (empty: all inside); see :func:`row_problems`."""
    out = []
    for i, row in enumerate(as_rows(A)):
        out += row_problems(c, names, score_range, q_limit, i, row, *score_and_q(c, row))
        if len(out) >= max_problems:
            break
    return out[:max_problems] if max_problems else out


def checked_predict(c: dict, names, score_range, q_limit: float, A, check_domain: bool = True) -> list[list[float]]:
    """KPI rows (order :data:`TARGETS`) of input rows A, after refusing inputs outside the domain
    (TwinInputError naming at most five problems)."""
    out, problems = [], []
    for i, row in enumerate(as_rows(A)):
        s, q = score_and_q(c, row)
        if check_domain and len(problems) < 5:
            problems += row_problems(c, names, score_range, q_limit, i, row, s, q)
        out.append(predict_row(c, row, s))
    if problems:
        raise TwinInputError("Input outside the surrogate's training domain (the surrogate does not "
                             "extrapolate; use the twin): " + " | ".join(problems[:5]))
    return out


@dataclass
class CompiledSurrogate:
    """A fitted surrogate as plain numbers: ``feature_names`` (the input columns, in order),
    ``arrays`` (the compiled pipeline, :data:`ARRAY_KEYS`), ``score_range`` and ``q_limit`` (the
    domain), ``metadata`` (what it was made from)."""

    feature_names: tuple
    arrays: dict
    score_range: list
    q_limit: float
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        self.arrays = plain(self.arrays)
        self.score_range = [[float(lo), float(hi)] for lo, hi in
                            (self.score_range.tolist() if hasattr(self.score_range, "tolist") else self.score_range)]
        self.q_limit = float(self.q_limit)

    def predict(self, A, check_domain: bool = True) -> list[list[float]]:
        """KPI rows, order :data:`TARGETS`, of input rows in the order of ``feature_names`` (or a
        table whose columns are named so: taken by name, never by position)."""
        if hasattr(A, "columns"):
            missing = [c for c in self.feature_names if c not in A.columns]
            if missing:
                raise TwinInputError(f"The 'X' of CompiledSurrogate lacks the columns {missing}.")
            A = A[list(self.feature_names)].to_numpy(float)
        rows = as_rows(A)
        bad = [len(r) for r in rows if len(r) != len(self.feature_names)]
        if bad:
            raise TwinInputError(f"The 'X' of CompiledSurrogate must have {len(self.feature_names)} columns "
                                 f"in the order of feature_names. Got a row of {bad[0]}.")
        return checked_predict(self.arrays, self.feature_names, self.score_range, self.q_limit, rows, check_domain)

    def save(self, path: str | Path) -> Path:
        """Write the numbers and the metadata to one JSON file (via a temporary file,
        :mod:`twin.atomic`)."""
        path = Path(path)
        doc = {"metadata": dict(self.metadata, compiled_format_version=COMPILED_FORMAT_VERSION),
               "feature_names": list(self.feature_names), "arrays": self.arrays,
               "score_range": self.score_range, "q_limit": self.q_limit}
        return write_text_atomically(path, json.dumps(doc, sort_keys=True, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "CompiledSurrogate":
        """Read a file written by :meth:`save`; TwinError for another format version."""
        path = Path(path)
        if not path.is_file():
            raise TwinError(f"No compiled surrogate {path}: run `python -m twin.surrogate --compile`.")
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
            meta = doc["metadata"]
        except (ValueError, KeyError, TypeError) as e:
            raise TwinError(f"Compiled surrogate {path} is not a grindtwin compiled surrogate ({e}). "
                            "Regenerate it: `python -m twin.surrogate --compile`.") from None
        if meta.get("compiled_format_version") != COMPILED_FORMAT_VERSION:
            raise TwinError(f"Compiled surrogate {path} has format version "
                            f"{meta.get('compiled_format_version')!r}; this code reads "
                            f"{COMPILED_FORMAT_VERSION}. Regenerate it: `python -m twin.surrogate --compile`.")
        return cls(tuple(doc["feature_names"]), doc["arrays"], doc["score_range"], doc["q_limit"], meta)


