"""Exception family of the ``twin`` package.

Every message names the field, the value and what is allowed, in one shape
(after scikit-learn): "The 'speed_frac_critical' parameter of Mill must be a float
in (0, 1). Got 1.3."
"""

from __future__ import annotations

import difflib
import numbers
from collections.abc import Iterable


class TwinError(Exception):
    """Base class of every error raised by ``twin``."""


class TwinInputError(TwinError, ValueError):
    """A value given by the user is outside what is allowed."""


class ModelError(TwinError):
    """A model cannot be assembled (unknown effect, missing requirement, bad b matrix)."""


class SolverError(TwinError, RuntimeError):
    """A numerical solver failed; the message carries the solver's own status."""


class OverloadError(SolverError):
    """No steady state: at this feed the mill fills beyond its shell (the input is out of the mill's
    range; a lower feed may have one)."""


class FastCalibrationWarning(UserWarning):
    """A calibration made with ``grindtwin calibrate --fast`` (a check of the machinery on a few
    particles) is in use: its numbers run, but are not to be predicted with."""


def bad_value(owner: str, field: str, value: object, allowed: str) -> TwinInputError:
    """Build the standard input error: field, value and what is allowed."""
    return TwinInputError(f"The '{field}' parameter of {owner} must be {allowed}. Got {value!r}.")


def close_matches(name: str, known: Iterable[str]) -> str:
    """' Did you mean ...?' suffix listing close matches of ``name`` among ``known``."""
    known = list(known)
    # a case slip first: difflib finds no match of one letter, 'b' for 'B'
    hits = [k for k in known if k.lower() == name.lower()] or difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    if hits:
        return " Did you mean " + " or ".join(repr(h) for h in hits) + "?"
    return ""


def check_range(owner: str, field: str, value: float, lo: float, hi: float,
                lo_open: bool = True, hi_open: bool = True) -> float:
    """Return ``float(value)`` if it lies in the interval, else raise :func:`bad_value`. A bool is
    refused: it is an int in Python, so True passed as 1.0 (a flag typed for a number)."""
    if isinstance(value, bool):
        raise bad_value(owner, field, value, _interval(lo, hi, lo_open, hi_open) + ", not a bool")
    if isinstance(value, (str, bytes)):  # "150" passed as 150.0 and was kept as text, failing far away
        raise bad_value(owner, field, value, _interval(lo, hi, lo_open, hi_open) + ", a number, not text")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise bad_value(owner, field, value, _interval(lo, hi, lo_open, hi_open)) from None
    ok_lo = v > lo if lo_open else v >= lo
    ok_hi = v < hi if hi_open else v <= hi
    if not (ok_lo and ok_hi) or v != v:
        raise bad_value(owner, field, value, _interval(lo, hi, lo_open, hi_open))
    return v


def check_int(owner: str, field: str, value, lo: int, hi: int) -> int:
    """``int(value)`` if it is an integer (numpy's too; not a bool, not a float) in [lo, hi], else
    :func:`bad_value`: np.int64(25) was refused as "not an integer"."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not lo <= value <= hi:
        raise bad_value(owner, field, value, f"an integer in [{lo}, {hi}]")
    return int(value)


def _interval(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    return f"a float in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
