"""Checking an environment's constructor arguments: one ValueError naming the argument and its range."""

from __future__ import annotations

import math
import numbers


def number(name, value, lo, hi, *, integer=False, lo_open=False):
    """``value`` as a float (or int with ``integer``) in [lo, hi] (``lo_open``: (lo, hi]); else a ValueError
    naming ``name``, its range and what was given (a string, NaN, a float count...)."""
    kind = "a whole number" if integer else "a number"
    ok_type = isinstance(value, numbers.Integral) if integer else isinstance(value, numbers.Real)
    if isinstance(value, bool) or not ok_type:
        raise ValueError(f"{name} must be {kind}, got {type(value).__name__} {value!r}")
    v = int(value) if integer else float(value)
    left = "(" if lo_open else "["
    if not math.isfinite(v) or not (lo < v if lo_open else lo <= v) or not v <= hi:
        raise ValueError(f"{name} must be {kind} in {left}{lo:g}, {hi:g}], got {value!r}")
    return v
