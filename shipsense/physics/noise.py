r"""Measurement noise models.

* Gaussian, per component standard deviation ``std``.
* Contaminated Gaussian (outliers): ``(1 - eps) N(0, R) + eps N(0, scale^2 R)``
  with ``scale = 10`` by default (Huber 1964; the seismic–magnetic study).
* Dropouts: each component missing independently with probability ``rate``;
  returned as a boolean *mask* (True = present).  Filters skip masked
  components exactly.
"""

from __future__ import annotations

import numpy as np


def gaussian(rng, std, shape):
    """Zero-mean Gaussian noise with per-component std broadcast against ``shape``."""
    return np.asarray(std, dtype=float) * rng.standard_normal(shape)


def contaminated(rng, std, shape, eps, scale=10.0):
    """Contaminated Gaussian noise: with probability ``eps`` the std is ``scale * std``."""
    outlier = rng.random(shape) < eps
    return np.where(outlier, scale, 1.0) * gaussian(rng, std, shape)


def dropout_mask(rng, shape, rate):
    """Boolean mask of present components; each is dropped with probability ``rate``."""
    if rate <= 0.0:
        return np.ones(shape, dtype=bool)
    return rng.random(shape) >= rate
