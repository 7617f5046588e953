"""Numbers for JSON reports: JSON has no NaN or infinity, so a value that is not finite (no bound, no
relaxation, a rank-deficient information) is written as ``null``."""

from __future__ import annotations

import numpy as np


def finite_or_none(x):
    """``float(x)``, or None where ``x`` is None or not finite."""
    return float(x) if x is not None and np.isfinite(x) else None


def jsonable(x):
    """``x`` with numpy arrays, scalars and tuples turned into JSON's types (recursively, dict keys as strings),
    and non-finite floats into None (:func:`finite_or_none`)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return finite_or_none(x)
    return x
