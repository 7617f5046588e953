r"""Fisher information of a passage, Cramér–Rao bounds, the posterior CRLB and bound maps.

A passage is its initial state :math:`\theta = x_0` (position, velocity and
the model's parameters, in the tracker model's internal units).  With the
deterministic constant-velocity motion :math:`x_k = A^k \theta`,

.. math::  J(\theta) = \sum_k \sum_j G_{jk}^T R_j^{-1} G_{jk}, \qquad
           G_{jk} = \frac{\partial h_j(x_k)}{\partial x}\, A^k,

additive over sensors (and channels), which is what makes sensor selection
convex.  The CRLB is :math:`J^{-1}`.  The posterior CRLB of the stochastic
recursion (Tichavský, Muravchik & Nehorai, IEEE TSP 1998) for additive
Gaussian noise and linear dynamics is

.. math::  J_{k+1} = (Q + A J_k^{-1} A^T)^{-1} + \mathbb{E}[H_{k+1}^T R^{-1} H_{k+1}],

the expectation taken over true trajectories (Monte Carlo over the given ones).
Jacobians are the models' analytic ones.

A passage with known manoeuvres (:class:`PassageMotion`) moves by its own motion :math:`x_k = f_k(\theta)`
instead, and :math:`A^k` above becomes the Jacobian :math:`\Phi_k = \partial x_k / \partial \theta
= F_{k-1} \cdots F_0` of that motion (:func:`~shipsense.design.manoeuvre_bound.passage_motion`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.models.transitions import powers
from shipsense.trackers.metrics import position_crlb_trace


def trajectory(model, theta, steps):
    """States ``A^k theta`` (..., K, n) of passages with initial states ``theta`` (..., n) (internal units)."""
    return np.einsum("kij,...j->...ki", powers(model.A, steps), np.asarray(theta, dtype=float))


@dataclass(frozen=True)
class PassageMotion:
    r"""The known motion of passages that do not keep a constant velocity (manoeuvring passages), internal
    units.

    Attributes
    ----------
    states : ndarray, shape (P, K, n)
        The states :math:`x_k = f_k(\theta)` at every sample.
    jacobians : ndarray, shape (P, K, n, n)
        :math:`\Phi_k = \partial x_k / \partial \theta` (:math:`\Phi_0 = I`).
    manoeuvring : ndarray of bool, shape (P,)
        Which passages manoeuvre (the others move at constant velocity).
    """

    states: np.ndarray
    jacobians: np.ndarray
    manoeuvring: np.ndarray

    def take(self, rows):
        """The motion of passages ``rows`` (a slice of the passage axis)."""
        return PassageMotion(self.states[rows], self.jacobians[rows], self.manoeuvring[rows])


def weighted_jacobian(model, theta, Ak, states=None):
    r"""Whitened Jacobian rows of passages about their initial states: :math:`R^{-1/2} H(A^k \theta) A^k`.

    Parameters
    ----------
    model : model with ``H`` and ``R`` (internal units)
    theta : ndarray, shape (..., n)
        Initial states (internal units).
    Ak : ndarray, shape (K, n, n) or (..., K, n, n)
        The transition's powers at the samples used (:func:`~shipsense.models.transitions.powers`), or each
        passage's own motion Jacobians :math:`\Phi_k` (:class:`PassageMotion`).
    states : ndarray, shape (..., K, n), optional
        The states at those samples (default :math:`A^k \theta`; a manoeuvring passage's own).

    Returns
    -------
    W : ndarray, shape (..., K, m, n)
        ``W^T W`` summed over samples and channels is the passage's Fisher information.
    """
    X = np.einsum("kij,...j->...ki", Ak, np.asarray(theta, dtype=float)) if states is None else states
    return (model.H(X) @ Ak) * (1.0 / np.sqrt(model.R))[:, None]


def passage_fim(model, theta, steps, per_sensor=False, stride=1, block=10_000, progress=None, motion=None):
    """Fisher information of passages about their initial state (internal units).

    Parameters
    ----------
    model : FieldModel (or any model with ``A``, ``H``, ``R``)
    theta : ndarray, shape (..., n)
        Initial states (internal units).
    steps : int
        Samples in the passage.
    per_sensor : bool
        Return one matrix per sensor, (..., S, n, n), instead of the sum.
    stride : int
        Use every ``stride``-th sample (and weight it by ``stride``): a cheaper
        approximation for long passages.
    block : int
        Jacobian rows (samples x sensors) evaluated at once: the samples are
        taken in blocks of about this many rows (whole passages at once made
        temporaries of hundreds of MB for large candidate sets; single
        samples paid Python overhead per call).
    progress : callable, optional
        Called with the fraction done after every block.
    motion : PassageMotion, optional
        The passages' own motion (``theta`` (P, n), ``steps`` samples): manoeuvring passages, whose
        information is taken along their true states with their motion's Jacobians (module docstring);
        default the constant velocity.

    Returns
    -------
    J : ndarray, shape (..., n, n) or (..., S, n, n)
    """
    theta = np.asarray(theta, dtype=float)
    Ak = powers(model.A, steps)[::stride]                     # (K, n, n)
    batch, n = theta.shape[:-1], theta.shape[-1]
    flat = theta.reshape(-1, n)
    if motion is not None:
        if motion.jacobians.shape != (len(flat), steps, n, n):
            raise ValueError(f"motion: {len(flat)} passages of {steps} samples and {n} states expected, "
                             f"got Jacobians of shape {motion.jacobians.shape}")
        motion = PassageMotion(motion.states[:, ::stride], motion.jacobians[:, ::stride], motion.manoeuvring)
    sensor = model.array.channel_sensor
    S = len(model.array.ids)
    order = np.argsort(sensor, kind="stable")
    starts = np.searchsorted(sensor[order], np.arange(S))
    per = len(sensor) // S if S else 0
    uniform = S > 0 and per * S == len(sensor) and np.array_equal(sensor[order], np.repeat(np.arange(S), per))
    K = len(Ak)
    m = len(sensor)

    def information(W):
        """(pb, kb, m, n) weighted Jacobian rows -> (pb, S, n, n) or (pb, n, n), summed over the samples."""
        if not per_sensor:
            return np.einsum("bkcn,bkcp->bnp", W, W)
        Ws = W[:, :, order]
        if uniform:   # the same number of channels per sensor: one batched product per sensor
            pb, kb = Ws.shape[:2]
            Ws = np.ascontiguousarray(Ws.reshape(pb, kb, S, per, n).transpose(0, 2, 1, 3, 4)).reshape(pb, S, -1, n)
            return np.swapaxes(Ws, -1, -2) @ Ws
        return np.add.reduceat(np.einsum("bkcn,bkcp->bcnp", Ws, Ws), starts, axis=1)

    out = np.zeros((len(flat), S, n, n) if per_sensor else (len(flat), n, n))
    total = len(flat) * K
    done = 0
    passages_per_block = block // max(1, K * m)
    if passages_per_block >= 1:       # short passages or small arrays: whole passages at once
        for b0 in range(0, len(flat), passages_per_block):
            th = flat[b0:b0 + passages_per_block]
            if motion is None:
                W = weighted_jacobian(model, th, Ak)
            else:
                mo = motion.take(slice(b0, b0 + len(th)))
                W = weighted_jacobian(model, th, mo.jacobians, mo.states)
            out[b0:b0 + len(th)] = information(W)
            done += len(th) * K
            if progress is not None:
                progress(done / total)
    else:                             # long passages past large arrays: blocks of samples
        per_block = max(1, block // max(1, m))
        for b, th in enumerate(flat):
            for k0 in range(0, K, per_block):
                if motion is None:
                    A = Ak[k0:k0 + per_block]
                    W = weighted_jacobian(model, th, A)                # (kb, m, n)
                else:
                    A = motion.jacobians[b, k0:k0 + per_block]
                    W = weighted_jacobian(model, th, A, motion.states[b, k0:k0 + per_block])
                out[b] += information(W[None])[0]
                done += len(A)
                if progress is not None:
                    progress(done / total)
    return stride * out.reshape(batch + out.shape[1:])


def crlb(J):
    """Cramér–Rao bound ``J^-1`` (pseudo-inverse where J is singular)."""
    return np.linalg.pinv(J, hermitian=True)


def pcrlb(model, states, J0, *, per_run=False, Q=None):
    """Posterior CRLB information matrices over time (Tichavský et al. 1998).

    Parameters
    ----------
    model : model with ``A``, ``Q``, ``H``, ``R`` (internal units)
    states : ndarray, shape (R, K, n)
        True state trajectories (internal units).
    J0 : ndarray, shape (n, n)
        Prior information at step 0 (inverse of the initial covariance).
    per_run : bool
        False: the measurement information is averaged over the R
        trajectories (one bound for the population, the Monte Carlo PCRLB).
        True: one bound per trajectory, from its own information.  For a
        population of different passages the mean of the per-passage bounds
        is the tighter figure (the inverse of a mean information is at most
        the mean of the inverses).
    Q : ndarray, shape (n, n), optional
        Process noise of the bound (default ``model.Q``); zero gives the CRLB
        of a deterministic trajectory (computed in information form).

    Returns
    -------
    bounds : ndarray, shape (K, n, n), or (R, K, n, n) with ``per_run``
        The bound ``J_k^-1`` on the error covariance at every step (step 0
        includes the first measurement, as the filters' first update does).
    """
    info = measurement_information(model, states, per_run=per_run)
    if not per_run:
        info = info[None] / np.asarray(states).shape[0]
    out = pcrlb_from_information(model, info, J0, Q=Q)
    return out if per_run else out[0]


def measurement_information(model, states, per_run=True):
    """Measurement information ``H^T R^-1 H`` along trajectories ``states`` (R, K, n) (internal units): per
    trajectory (R, K, n, n), or summed over them (K, n, n) -- a sum can be pooled across batches of
    passages before :func:`pcrlb_from_information`."""
    states = np.asarray(states, dtype=float)
    Hw = model.H(states) / np.sqrt(model.R)[:, None]          # (R, K, m, n)
    return np.einsum("rkcn,rkcp->rknp" if per_run else "rkcn,rkcp->knp", Hw, Hw)


def pcrlb_from_information(model, info, J0, Q=None, F=None):
    """The (P)CRLB recursion of :func:`pcrlb` from measurement information ``info`` (R, K, n, n): bounds
    (R, K, n, n).

    ``F`` (R or 1, K-1, n, n), optional: the transition of every step instead of ``model.A``, the bound
    conditional on a known sequence of motions (a manoeuvring passage's true turns and speed changes,
    :mod:`shipsense.design.manoeuvre_bound`): :math:`J_{k+1} = (Q + F_k J_k^{-1} F_k^T)^{-1} + I_{k+1}`.
    ``Q`` may then be per step too, (R or 1, K-1, n, n).
    """
    A = model.A
    Q = model.Q if Q is None else np.asarray(Q, dtype=float)
    deterministic = not np.any(Q)
    K = info.shape[1]
    out = np.empty(info.shape)
    J = J0 + info[:, 0]
    out[:, 0] = np.linalg.inv(J)
    if F is not None:
        F = np.asarray(F, dtype=float)
        for k in range(1, K):
            Fk = F[:, k - 1]
            if deterministic:   # J_k = F^-T J_{k-1} F^-1 + I_k
                G = np.linalg.solve(np.swapaxes(Fk, -1, -2), J)
                J = np.swapaxes(np.linalg.solve(np.swapaxes(Fk, -1, -2), np.swapaxes(G, -1, -2)), -1, -2)
                J = J + info[:, k]
            else:
                Qk = Q if Q.ndim == 2 else Q[:, k - 1]
                J = np.linalg.inv(Qk + Fk @ out[:, k - 1] @ np.swapaxes(Fk, -1, -2)) + info[:, k]
            out[:, k] = np.linalg.inv(J)
        return out
    Ainv = np.linalg.inv(A)
    for k in range(1, K):
        if deterministic:   # J_k = A^-T J_{k-1} A^-1 + I_k
            J = Ainv.T @ J @ Ainv + info[:, k]
        else:
            J = np.linalg.inv(Q + A @ out[:, k - 1] @ A.T) + info[:, k]
        out[:, k] = np.linalg.inv(J)
    return out


def bound_map(model, xs, ys, velocity, params, steps=21, per_sensor=True):
    """Position bound over a grid of target positions.

    For each grid point, a passage segment of ``steps`` samples with the given
    velocity (m/s) and parameters (internal units: moment or (z, p)) centred
    on the point; the value is ``sqrt(trace)`` of the position CRLB at the
    centre sample, in metres (inf where the information is singular).

    Returns
    -------
    bound : ndarray, shape (len(ys), len(xs))
    per_sensor : ndarray, shape (S, len(ys), len(xs))
        The bound with only that sensor (None unless ``per_sensor``: it costs
        one pseudo-inverse per sensor and grid point).
    """
    X, Y = np.meshgrid(np.asarray(xs, float), np.asarray(ys, float))
    half = (steps - 1) / 2 * model.period
    v = np.asarray(velocity, float)
    theta = np.zeros(X.shape + (model.n,))
    theta[..., 0] = X - half * v[0]
    theta[..., 1] = Y - half * v[1]
    theta[..., 2:4] = v
    theta[..., 4:] = params
    Js = passage_fim(model, theta, steps, per_sensor=per_sensor)     # (ny, nx, [S,] n, n)
    centre = powers(model.A, steps)[(steps - 1) // 2]

    def pos_bound(J):
        C = centre @ crlb(J) @ centre.T
        val = np.sqrt(np.clip(position_crlb_trace(model.cov_to_si(C)), 0, None))
        rank = np.linalg.matrix_rank(J, hermitian=True)
        return np.where(rank < model.n, np.inf, val)

    if not per_sensor:
        return pos_bound(Js), None
    return pos_bound(Js.sum(axis=-3)), np.moveaxis(pos_bound(Js), -1, 0)
