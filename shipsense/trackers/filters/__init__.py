"""Filter units: one interface, batched over leading axes.

>>> from shipsense.trackers.filters import get_filter
>>> ukf = get_filter("ukf")
>>> # belief = ukf.predict(belief, model); belief, innovation = ukf.update(belief, y, model, mask)

Every unit shares :func:`~shipsense.trackers.filters.core.predict` (the
motion models are linear) and differs in its measurement update:

============== ===========================================================
``ekf``        extended KF, analytic Jacobians
``ukf``        unscented KF (``alpha``, ``beta``, ``kappa``; default 1, 2, 0)
``ckf``        cubature KF, 2n equally weighted points
``cdkf``       central-difference KF, Stirling interpolation, ``h = sqrt(3)``
``srcdkf``     square-root CDKF (QR-propagated Cholesky factors)
``puekf``      progressive-update EKF (``n_pu`` sub-updates with ``R n_pu``)
``huber_ukf``  Huber-robust UKF (``gamma`` = 1.345, iterated reweighting)
============== ===========================================================
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass, field

from shipsense.models.measurement import kernel_of
from shipsense.trackers.filters import cdkf, ckf, ekf, fused, huber_ukf, puekf, srcdkf, ukf
from shipsense.trackers.filters.core import Belief, Innovation, predict, safe_cholesky, tria

UPDATES: dict[str, Callable] = {
    "ekf": ekf.update, "ukf": ukf.update, "ckf": ckf.update, "cdkf": cdkf.update,
    "srcdkf": srcdkf.update, "puekf": puekf.update, "huber_ukf": huber_ukf.update,
}
FILTER_NAMES = tuple(UPDATES)


@dataclass(frozen=True)
class FilterUnit:
    """A filter unit: a name, its update function and options (e.g. ``n_pu``, ``gamma``)."""

    name: str
    options: dict = field(default_factory=dict)

    def on(self, model):
        """This unit's steps on ``model``, their implementation chosen here, once: the compiled kernels
        (:class:`CompiledSteps`) for a model with a compiled measurement kernel
        (:func:`~shipsense.models.measurement.kernel_of`), the numpy steps of the filter modules otherwise
        (:class:`NumpySteps`).  What the bank and :func:`~shipsense.trackers.filters.run.run_filter` step
        with."""
        last = self.__dict__.get("_last")   # the steps on the model of the last call, while that model lives
        if last is not None and last[0]() is model:
            return last[1]
        spec = kernel_of(model)
        steps = NumpySteps(self) if spec is None else CompiledSteps(self, spec)
        try:
            object.__setattr__(self, "_last", (weakref.ref(model), steps))
        except TypeError:                    # (a model that takes no weak reference: chosen again next time)
            pass
        return steps

    def __getstate__(self):
        """The unit's fields (copied and pickled without the steps :meth:`on` keeps)."""
        return {"name": self.name, "options": self.options}

    def predict(self, belief: Belief, model) -> Belief:
        """Time update (shared; the SR-CDKF propagates its factor by triangularisation), by :meth:`on`'s
        steps."""
        return self.on(model).predict(belief, model)

    def step(self, belief: Belief, y, model, mask=None):
        """Time update then measurement update (:meth:`predict` then :meth:`update`); returns ``(belief,
        innovation)``."""
        return self.on(model).step(belief, y, model, mask)

    def update(self, belief: Belief, y, model, mask=None):
        """Measurement update, by :meth:`on`'s steps; returns ``(belief, innovation)``."""
        return self.on(model).update(belief, y, model, mask)


class NumpySteps:
    """A unit's numpy steps: :func:`~shipsense.trackers.filters.core.predict` and the update of its module
    (``ukf.update`` and so on), the generic implementation, for a model without a compiled kernel (a user's own
    ``h``, the series HED path)."""

    __slots__ = ("unit",)      # (a plain class: FilterUnit's steps are made on every call of theirs)

    def __init__(self, unit):
        self.unit = unit

    def predict(self, belief: Belief, model) -> Belief:
        return predict(belief, model, square_root=self.unit.name == "srcdkf")

    def update(self, belief: Belief, y, model, mask=None):
        return UPDATES[self.unit.name](belief, y, model, mask, **self.unit.options)

    def step(self, belief: Belief, y, model, mask=None):
        return self.update(self.predict(belief, model), y, model, mask)


class CompiledSteps:
    """A unit's compiled steps on a model with a compiled measurement kernel ``spec``
    (:mod:`~shipsense.trackers.filters.fused`).  A step in which an element fails numerically (a covariance
    that is not positive definite, a result that is not finite) is taken again by the numpy steps, which flag
    and repair such an element (the compiled kernels stop at it)."""

    __slots__ = ("unit", "spec")

    def __init__(self, unit, spec):
        self.unit, self.spec = unit, spec

    def predict(self, belief: Belief, model) -> Belief:
        square_root = self.unit.name == "srcdkf"
        out = fused.predict(belief, model, square_root)
        return out if out is not None else predict(belief, model, square_root=square_root)

    def update(self, belief: Belief, y, model, mask=None):
        out = fused.update(self.unit.name, belief, y, model, self.spec, mask, **self.unit.options)
        return out if out is not None else UPDATES[self.unit.name](belief, y, model, mask, **self.unit.options)

    def step(self, belief: Belief, y, model, mask=None):
        return self.update(self.predict(belief, model), y, model, mask)


def get_filter(name: str, **options) -> FilterUnit:
    """The filter unit called ``name`` with keyword ``options`` for its update."""
    if name not in UPDATES:
        raise ValueError(f"unknown filter {name!r}; choose one of: {', '.join(FILTER_NAMES)}")
    allowed = _options_of(name)
    for key in options:   # checked here: the compiled steps read only the options they know
        if key not in allowed:
            raise ValueError(f"{name}: unknown option {key!r}; it takes: {', '.join(allowed) or 'no options'}")
    return FilterUnit(name, dict(options))


def _options_of(name):
    """The keyword options of a unit's update (its parameters after ``belief, y, model, mask``)."""
    import inspect

    return tuple(inspect.signature(UPDATES[name]).parameters)[4:]


__all__ = ["FILTER_NAMES", "Belief", "CompiledSteps", "FilterUnit", "Innovation", "NumpySteps", "get_filter", "predict",
           "safe_cholesky", "tria"]
