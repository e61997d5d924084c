"""Input checks shared by the model, the scenes, the env and the CLI: one message style."""

from __future__ import annotations

import math
import numbers

import numpy as np


def check_range(
    name: str,
    value,
    lo: float,
    hi: float,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    allow_inf: bool = False,
    allowed: str | None = None,
) -> float:
    """Return ``float(value)`` or raise ValueError naming ``name`` and the allowed range.

    NaN is always rejected; +inf only with ``allow_inf``; booleans too (``True`` is not the
    number 1.0 here: a flag passed where a number belongs is a mistake).  ``allowed``: what
    the messages say the value must be, where the caller admits less than [lo, hi] (e.g. "0,
    inf or in [1e-100, 1e+100]") and checks the rest itself with the same words.
    """
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a number, got the boolean {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    except OverflowError:  # an integer beyond the float range (10**400)
        must = allowed or f"in {_range(lo, hi, lo_open, hi_open, allow_inf)}"
        raise ValueError(
            f"{name} must be {must}, got an integer too large for a float "
            f"({len(str(abs(value)))} digits)"
        ) from None
    if math.isnan(x):
        must = allowed or f"in {_range(lo, hi, lo_open, hi_open, allow_inf)}"
        raise ValueError(f"{name} must be {must}, got NaN")
    if math.isinf(x) and x > 0 and allow_inf:
        return x
    bad = (
        x < lo
        or x > hi
        or (lo_open and x == lo)
        or (hi_open and x == hi)
        or (math.isinf(x) and not allow_inf)
    )
    if bad:
        must = allowed or (
            f"in {_range(lo, hi, lo_open, hi_open, allow_inf)}" + (" or inf" if allow_inf else "")
        )
        raise ValueError(f"{name} must be {must}, got {x!r}")
    return x


def check_int(name: str, value, lo: int, hi: int) -> int:
    """Return ``int(value)`` or raise ValueError naming ``name`` and the allowed range
    [lo, hi]: an integer (integral floats such as 2.0 accepted, never truncated: 2.5 is
    refused), not a boolean, NaN, inf or None."""
    ok = (
        isinstance(value, numbers.Real)
        and not isinstance(value, (bool, np.bool_))
        and lo <= value <= hi
        and value == int(value)
    )  # range first: no int(inf)
    if not ok:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def _range(lo, hi, lo_open, hi_open, allow_inf) -> str:
    """The allowed range as the messages write it (built only for an error: formatting it for
    every check was 11% of a working point's time at 8 springs/a1)."""
    if math.isinf(lo) and math.isinf(hi) and not allow_inf:
        return "(-inf, inf) (a finite number)"
    return f"{'(' if lo_open else '['}{_fmt(lo)}, {_fmt(hi)}{')' if hi_open else ']'}"


def as_real_array(name: str, x) -> np.ndarray:
    """``x`` as a float64 array, or ValueError naming ``name`` for strings, booleans, complex
    numbers, objects and ragged nested sequences (which numpy would convert or reject with a
    message that names no parameter)."""
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError):  # ragged nested sequences
        raise ValueError(f"{name} must be a real number or array of them, got {x!r}") from None
    if raw.dtype.kind not in "fiu":
        raise ValueError(
            f"{name} must be a real number or array of them, got {x!r} (dtype {raw.dtype})"
        )
    return raw.astype(np.float64)


def _fmt(v: float) -> str:
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:g}"
