"""The models' compiled measurement functions: readings and Jacobians of one state at a time, for numba loops.

A model with a compiled kernel describes itself to it by ``kernel_spec()`` (a tuple of arrays and numbers:
:meth:`~shipsense.models.field_model.FieldModel.kernel_spec` for magnetometers, seismic bearings and electrodes on
the fast HED path (:mod:`shipsense.physics.hed_kernel`'s point functions),
:meth:`~shipsense.models.field_model.LinearModel.kernel_spec`); :func:`kernel_of` caches it per model.
The filters' compiled steps (:mod:`shipsense.trackers.filters.fused`) call :func:`measure` and
:func:`measure_jacobian` inside their loops; :func:`readings` and :func:`h_and_jacobian` are the same kernel
over a batch of states (what :meth:`~shipsense.models.field_model.FieldModel.h` and ``h_and_H`` run for those
models).  The numpy kernels of :mod:`shipsense.physics` are the independent reference
(tests/models/test_field_model.py, tests/trackers/filters/test_fused.py).
"""

from __future__ import annotations

import math
import weakref

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.parallel import in_chunks
from shipsense.physics.hed_kernel import hed_field_point, hed_point
from shipsense.physics.kernels import dipole_point, dipole_point_jacobian

FIELD, LINEAR = 0, 1
VECTOR, MAGNITUDE, TMI, BEARING, E_VECTOR, ENVELOPE, E_MAGNITUDE = range(7)
"""Sensor codes of ``kernel_spec()``: magnetometers (vector, magnitude, tmi), seismic bearings, electrodes
(vector, envelope, magnitude)."""
_KERNELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

# The loops over the batch are compiled without numba's reference counting (``_nrt=False``; they allocate
# nothing: the kernels that call them allocate the scratch).  With it, every array handed to an inlined helper,
# unpacked from a tuple or sliced as a view costs an atomic increment and decrement that numba does not always
# prune in a loop with branches: several times the cost of the measurement function itself, and most of a UKF
# update at large batches.  ``_nrt`` is a numba option that is not part of its documented API; a numba
# without it gets the counted loops (same results, slower).
try:
    loop_jit = njit(cache=True, error_model="numpy", nogil=True, _nrt=False)
except (KeyError, TypeError, ValueError):      # pragma: no cover - a numba without the option
    loop_jit = njit(cache=True, error_model="numpy", nogil=True)


_CODES = {("magnetometer", "vector"): VECTOR, ("magnetometer", "magnitude"): MAGNITUDE, ("magnetometer", "tmi"): TMI,
          ("accelerometer", "bearing"): BEARING, ("electrode", "vector"): E_VECTOR, ("electrode", "envelope"): ENVELOPE,
          ("electrode", "magnitude"): E_MAGNITUDE}


def sensor_codes(types, kinds):
    """The kernel's code of each sensor (type, measurement kind), (S,) int64."""
    return np.array([_CODES[(t, k)] for t, k in zip(types, kinds)], dtype=np.int64)


def kernel_of(model):
    """The compiled measurement kernel's description of ``model`` (its ``kernel_spec()``), or None.

    None means the model has no compiled kernel and the filters run their numpy steps.
    """
    base = getattr(model, "_model", model)    # a stepped model measures as its base model
    try:
        return _KERNELS[base]
    except (KeyError, TypeError):
        pass
    describe = getattr(base, "kernel_spec", None)
    spec = describe() if describe is not None else None
    try:
        _KERNELS[base] = spec
    except TypeError:
        pass
    return spec


@njit(cache=True, error_model="numpy", inline="always")
def wrap_angle(a):
    """An axial angle (defined modulo pi) wrapped into [-pi/2, pi/2) (:func:`~shipsense.physics.seismic.wrap_axial`)."""
    return a - math.pi * math.floor((a + 0.5 * math.pi) / math.pi)


@njit(cache=True, error_model="numpy", inline="always")
def _source(x, cols, zsrc):
    """The source height and the keel dipole ``p v / |v|`` (zero at rest) of internal state ``x``, with the
    dipole's unit direction and ``p / |v|`` for derivatives (``p`` at rest, where the direction is undefined:
    as the numpy path); no dipole without electrodes."""
    iz = cols[1]
    if iz < 0:
        return zsrc, 0.0, 0.0, 0.0, 0.0, 0.0
    speed = math.sqrt(x[2] * x[2] + x[3] * x[3])
    ux, uy = (x[2] / speed, x[3] / speed) if speed > 0 else (0.0, 0.0)
    p = x[iz + 1]
    return x[iz], p * ux, p * uy, ux, uy, (p / speed if speed > 0 else p)


@njit(cache=True, error_model="numpy", inline="always")
def measure(x, spec, out, B):
    """Predicted measurements of one internal state ``x`` into ``out`` (m,); ``B`` (3,) is scratch."""
    kind, sens, orient, code, earth, offs, C, mscale, zsrc, axial, cols, hed, table = spec
    if kind == LINEAR:
        for i in range(C.shape[0]):
            acc = 0.0
            for j in range(C.shape[1]):
                acc += C[i, j] * x[j]
            out[i] = acc
        return
    im = cols[0]
    zq, dpx, dpy = _source(x, cols, zsrc)[:3]
    for s in range(sens.shape[0]):
        k = offs[s]
        c = code[s]
        if c == BEARING:
            out[k] = wrap_angle(math.atan2(x[1] - sens[s, 1], x[0] - sens[s, 0]))
            continue
        if c >= E_VECTOR:
            B[0], B[1], B[2] = hed_field_point(sens[s, 0] - x[0], sens[s, 1] - x[1], sens[s, 2], zq, dpx, dpy, table,
                                               cols[2], cols[3], hed[0], hed[1], hed[2], hed[3], hed[4], hed[5],
                                               hed[6], hed[7], hed[8])
        else:
            dipole_point(sens[s, 0] - x[0], sens[s, 1] - x[1], sens[s, 2] - zq, x[im] * mscale, x[im + 1] * mscale,
                         x[im + 2] * mscale, B)
        if c == VECTOR or c == E_VECTOR or c == ENVELOPE:
            for i in range(3):
                v = orient[s, 0, i] * B[0] + orient[s, 1, i] * B[1] + orient[s, 2, i] * B[2]
                out[k + i] = abs(v) if c == ENVELOPE else v
        elif c == MAGNITUDE or c == E_MAGNITUDE:
            out[k] = math.sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2])
        else:
            out[k] = B[0] * earth[0] + B[1] * earth[1] + B[2] * earth[2]


@njit(cache=True, error_model="numpy", inline="always")
def measure_jacobian(x, spec, out, J, r, mom, B, dBq, dBm):
    """``h(x)`` into ``out`` (m,) and its Jacobian into ``J`` (m, n); the last five arguments are scratch.

    The electric field's derivatives in the source (dE/dq, 3 x 3) and the dipole (dE/dp, 3 x 2) take the places
    of the magnetic ``dBq`` and ``dBm``, then the chain rule through ``p v / |v|`` (:meth:`FieldModel._h_and_H_numpy`).
    """
    kind, sens, orient, code, earth, offs, C, mscale, zsrc, axial, cols, hed, table = spec
    if kind == LINEAR:
        measure(x, spec, out, B)
        for i in range(C.shape[0]):
            for j in range(C.shape[1]):
                J[i, j] = C[i, j]
        return
    J[:, :] = 0.0
    im, iz = cols[0], cols[1]
    zq, dpx, dpy, ux, uy, pv = _source(x, cols, zsrc)
    for s in range(sens.shape[0]):
        k = offs[s]
        c = code[s]
        if c == BEARING:      # d atan2(dy, dx) / d(x, y) = (-dy, dx) / (dx^2 + dy^2)
            dx, dy = x[0] - sens[s, 0], x[1] - sens[s, 1]
            out[k] = wrap_angle(math.atan2(dy, dx))
            r2 = dx * dx + dy * dy
            J[k, 0] = -dy / r2
            J[k, 1] = dx / r2
            continue
        electric = c >= E_VECTOR
        if electric:
            hed_point(sens[s, 0] - x[0], sens[s, 1] - x[1], sens[s, 2], zq, dpx, dpy, table, cols[2], cols[3],
                      hed[0], hed[1], hed[2], hed[3], hed[4], hed[5], hed[6], hed[7], hed[8], B, dBq, dBm)
        else:
            mom[0], mom[1], mom[2] = x[im] * mscale, x[im + 1] * mscale, x[im + 2] * mscale
            r[0], r[1], r[2] = sens[s, 0] - x[0], sens[s, 1] - x[1], sens[s, 2] - zq
            dipole_point_jacobian(r, mom, B, dBq, dBm)
        width = 3 if c == VECTOR or c == E_VECTOR or c == ENVELOPE else 1
        for i in range(width):
            if width == 3:      # the sensor's axis i: column i of its orientation
                w0, w1, w2 = orient[s, 0, i], orient[s, 1, i], orient[s, 2, i]
            elif c == TMI:
                w0, w1, w2 = earth[0], earth[1], earth[2]
            else:               # a magnitude: the field's unit vector (zero where the field vanishes)
                nb = math.sqrt(B[0] * B[0] + B[1] * B[1] + B[2] * B[2])
                d = nb if nb > 0 else 1.0
                w0, w1, w2 = B[0] / d, B[1] / d, B[2] / d
            v = w0 * B[0] + w1 * B[1] + w2 * B[2]
            sg = 1.0
            if c == ENVELOPE:   # |E_i|: the derivative is sign(E_i) times the field's (0 where it vanishes)
                sg = 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
                v = abs(v)
            out[k + i] = v
            for j in range(3):
                if j < 2 or iz >= 0:
                    J[k + i, j if j < 2 else iz] = sg * (w0 * dBq[0, j] + w1 * dBq[1, j] + w2 * dBq[2, j])
            if electric:        # d/dp along v/|v|, and d(p v/|v|)/dv = p (I - vhat vhat^T) / |v|
                gx = sg * (w0 * dBm[0, 0] + w1 * dBm[1, 0] + w2 * dBm[2, 0])
                gy = sg * (w0 * dBm[0, 1] + w1 * dBm[1, 1] + w2 * dBm[2, 1])
                J[k + i, iz + 1] = gx * ux + gy * uy
                J[k + i, 2] = pv * (gx * (1.0 - ux * ux) - gy * (ux * uy))
                J[k + i, 3] = pv * (gy * (1.0 - uy * uy) - gx * (ux * uy))
            else:
                for j in range(3):
                    J[k + i, im + j] = sg * mscale * (w0 * dBm[0, j] + w1 * dBm[1, j] + w2 * dBm[2, j])


@njit(cache=True, error_model="numpy", nogil=True)
def batch_kernel(X, spec, out, J, jacobian):
    """``h`` (B, m) of every internal state in ``X`` (B, n) into ``out`` and, with ``jacobian``, its Jacobian
    (B, m, n) into ``J``."""
    n, m = X.shape[1], out.shape[1]
    batch_loop(X, spec, out, J, jacobian, np.empty(n), np.empty(m), np.empty((m, n)), np.empty(3), np.empty(3),
                np.empty(3), np.empty((3, 3)), np.empty((3, 3)))
    return True


@loop_jit
def batch_loop(X, spec, out, J, jacobian, x, yhat, H, r3, m3, B, dBq, dBm):
    nb, n = X.shape
    m = out.shape[1]
    for b in range(nb):
        for a in range(n):
            x[a] = X[b, a]
        if jacobian:
            measure_jacobian(x, spec, yhat, H, r3, m3, B, dBq, dBm)
            for i in range(m):
                for a in range(n):
                    J[b, i, a] = H[i, a]
        else:
            measure(x, spec, yhat, B)
        for i in range(m):
            out[b, i] = yhat[i]


def _evaluate(model, x, jacobian):
    """:func:`batch_kernel` over the states ``x`` (..., n), the batch in chunks on the CPUs; None if the model
    has no compiled field kernel or ``x`` is complex (complex-step derivatives run the numpy kernels)."""
    spec = kernel_of(model)
    x = np.asarray(x)
    if spec is None or spec[0] != FIELD or x.dtype.kind not in "fiub":
        return None
    batch, n, m = x.shape[:-1], x.shape[-1], model.m
    X = np.ascontiguousarray(x.reshape(-1, n), dtype=float)
    if not X.flags.writeable:
        X = X.copy()
    out = np.empty((X.shape[0], m))
    J = np.empty((X.shape[0], m, n) if jacobian else (1, 1, 1))
    in_chunks(lambda lo, hi: batch_kernel(X[lo:hi], spec, out[lo:hi], J[lo:hi] if jacobian else J, jacobian),
              X.shape[0])
    return (out.reshape(batch + (m,)), J.reshape(batch + (m, n))) if jacobian else out.reshape(batch + (m,))


def h_and_jacobian(model, x):
    """``(h(x), dh/dx)`` of real internal states ``x`` (..., n) through the compiled measurement kernel -- the
    readings (..., m) and the Jacobian (..., m, n) in internal units, as
    :meth:`~shipsense.models.field_model.FieldModel.h_and_H` -- or None (no compiled kernel, or complex ``x``)."""
    return _evaluate(model, x, True)


def readings(model, x):
    """``h(x)`` of real internal states ``x`` (..., n) through the compiled measurement kernel (..., m), as
    :meth:`~shipsense.models.field_model.FieldModel.h`; None if the model has no compiled kernel or ``x`` is
    complex (complex-step derivatives run the numpy kernels)."""
    return _evaluate(model, x, False)


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
