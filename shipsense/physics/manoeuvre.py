r"""Manoeuvring motion: coordinated turns and along-track speed changes, integrated exactly.

A passage's horizontal motion is piecewise: nearly constant velocity (CV) between manoeuvres, a coordinated turn
(CT) at a constant rate :math:`\omega` during a turn, and a constant acceleration :math:`a` along the course
during a speed change (Li & Jilkov 2003, §§ III–IV; Bar-Shalom, Li & Kirubarajan 2001, §11.7).  With the
course angle :math:`\psi` (from the x axis, counter-clockwise: a positive rate turns to port) and the speed
:math:`s`, a piece of duration :math:`\tau` moves the ship by

.. math::  p(\tau) = p + s \begin{bmatrix}\cos\psi & -\sin\psi\\ \sin\psi & \cos\psi\end{bmatrix}
           \begin{bmatrix} S \\ C \end{bmatrix} + \tfrac12 a \tau^2 u(\psi), \qquad
           S = \frac{\sin\omega\tau}{\omega}, \quad C = \frac{1-\cos\omega\tau}{\omega},

:math:`\psi(\tau) = \psi + \omega\tau`, :math:`s(\tau) = s + a\tau`, :math:`u(\psi) = (\cos\psi, \sin\psi)`;
a piece has :math:`\omega = 0` (CV, speed change) or :math:`a = 0` (CV, turn), never both nonzero, so the
formula is exact for every piece (:math:`S \to \tau`, :math:`C \to 0` as :math:`\omega \to 0`, computed
through ``sinc`` without cancellation).  In state form :math:`x = (p_x, p_y, v_x, v_y)` the turn is the
linear map :math:`f_{CT}(x, \tau)` (Bar-Shalom et al. eq. 11.7.1-4) and the speed change
:math:`v \mapsto v + a\tau\, v/|v|`; :func:`transition_jacobians` gives the Jacobian of one sampling period.

The magnetic moment of a turning ship: its permanent part turns with the hull, its induced part stays with
the Earth's field.  With the body-fixed share :math:`\sigma` of the moment :math:`m_0` at the start of the
passage and the course change :math:`\Delta\psi` since then,

.. math::  m(\Delta\psi) = (1 - \sigma)\, m_0 + \sigma R_z(\Delta\psi)\, m_0 .

A schedule (:class:`Manoeuvres`) holds every run's manoeuvres as arrays (runs, M), sorted by start and
padded with empty slots, so that the motion of all runs is evaluated at once (a loop over the 2M + 1 pieces,
not over runs).

References
----------
X. R. Li and V. P. Jilkov, "Survey of maneuvering target tracking, Part I: dynamic models", IEEE Trans.
Aerospace and Electronic Systems 39(4), 1333–1364, 2003.
Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
Wiley 2001, ch. 11.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STRAIGHT, TURN, SPEED_CHANGE = 0, 1, 2
"""Per-sample manoeuvre labels: straight (constant velocity), in a turn, in a speed change."""
LABELS = ("straight", "turn", "speed_change")
"""Names of the labels, indexed by label."""


@dataclass(frozen=True)
class Manoeuvres:
    """The manoeuvres of a batch of passages.

    Attributes
    ----------
    kind : ndarray of int, shape (runs, M)
        :data:`TURN`, :data:`SPEED_CHANGE`, or :data:`STRAIGHT` for an empty slot.
    start : ndarray, shape (runs, M)
        Start of each manoeuvre, s since the passage start (inf in an empty slot); sorted in each run.
    duration : ndarray, shape (runs, M)
        Duration, s (0 in an empty slot).
    rate : ndarray, shape (runs, M)
        Turn rate :math:`\\omega`, rad/s (0 but in turns).
    acceleration : ndarray, shape (runs, M)
        Along-track acceleration :math:`a`, m/s² (0 but in speed changes).
    body_fixed_share : float
        Share :math:`\\sigma` of the magnetic moment that turns with the hull, in [0, 1].
    """

    kind: np.ndarray
    start: np.ndarray
    duration: np.ndarray
    rate: np.ndarray
    acceleration: np.ndarray
    body_fixed_share: float = 0.0

    @classmethod
    def none(cls, runs: int, body_fixed_share: float = 0.0) -> Manoeuvres:
        """No manoeuvre in any of ``runs`` passages (M = 0)."""
        z = np.zeros((runs, 0))
        return cls(z.astype(np.int8), z, z, z, z, float(body_fixed_share))

    @classmethod
    def from_slots(cls, kind, start, duration, rate, acceleration, body_fixed_share=0.0) -> Manoeuvres:
        """A schedule from per-run slots (runs, M) in any order: empty slots (kind :data:`STRAIGHT` or zero
        duration) are cleared and every run's manoeuvres sorted by start."""
        kind = np.asarray(kind, dtype=np.int8)
        duration = np.asarray(duration, dtype=float)
        empty = (kind == STRAIGHT) | ~(duration > 0)
        start = np.where(empty, np.inf, np.asarray(start, dtype=float))
        order = np.argsort(start, axis=1, kind="stable")

        def take(a):
            return np.take_along_axis(np.where(empty, 0, a), order, axis=1)
        return cls(take(kind).astype(np.int8), np.take_along_axis(start, order, axis=1), take(duration),
                   take(np.asarray(rate, dtype=float)), take(np.asarray(acceleration, dtype=float)),
                   float(body_fixed_share))

    def take(self, rows) -> Manoeuvres:
        """The schedule of the runs ``rows`` (a slice or indices)."""
        return Manoeuvres(self.kind[rows], self.start[rows], self.duration[rows], self.rate[rows],
                          self.acceleration[rows], self.body_fixed_share)

    @property
    def runs(self) -> int:
        return self.kind.shape[0]

    @property
    def any(self) -> bool:
        """Whether any passage manoeuvres."""
        return bool(np.any(self.kind != STRAIGHT))

    def pieces(self):
        """The 2M + 1 pieces of every run's motion: ``(t0, t1, rate, acceleration, label)``, each (runs, P).

        Piece 0 runs from -inf (anchored at t = 0) to the first manoeuvre; then each manoeuvre and the
        straight stretch after it.  Pieces of empty slots start at inf (never active).
        """
        R, M = self.kind.shape
        end = self.start + self.duration
        t0 = np.empty((R, 2 * M + 1))
        t1 = np.empty((R, 2 * M + 1))
        t0[:, 0] = -np.inf
        t0[:, 1::2], t0[:, 2::2] = self.start, end
        t1[:, :-1], t1[:, -1] = t0[:, 1:], np.inf
        rate = np.zeros((R, 2 * M + 1))
        acc = np.zeros((R, 2 * M + 1))
        label = np.zeros((R, 2 * M + 1), dtype=np.int8)
        rate[:, 1::2], acc[:, 1::2], label[:, 1::2] = self.rate, self.acceleration, self.kind
        return t0, t1, rate, acc, label

    def to_records(self) -> list[list[dict]]:
        """Every run's manoeuvres as plain records (kind name, start s, duration s, rate_deg_s, acceleration
        m/s²): the schedule written next to the truth."""
        out = []
        for r in range(self.runs):
            out.append([{"kind": LABELS[int(k)], "start": float(s), "duration": float(d),
                         "rate_deg_s": float(np.rad2deg(w)), "acceleration": float(a)}
                        for k, s, d, w, a in zip(self.kind[r], self.start[r], self.duration[r], self.rate[r],
                                                 self.acceleration[r]) if k != STRAIGHT])
        return out


def advance(p, speed, psi, tau, rate, acceleration):
    """Exact motion over ``tau`` s of a piece with turn rate ``rate`` (rad/s) and along-track
    ``acceleration`` (m/s²), never both nonzero (module equations).

    p : (..., 2) m; speed, psi, tau, rate, acceleration : (...) broadcastable.
    Returns ``(p, speed, psi)`` after ``tau``.
    """
    x = rate * tau
    S = tau * np.sinc(x / np.pi)                             # sin(w tau) / w
    C = 0.5 * x * tau * np.sinc(x / (2 * np.pi)) ** 2         # (1 - cos(w tau)) / w
    c, s = np.cos(psi), np.sin(psi)
    along = speed * S + 0.5 * acceleration * tau * tau
    across = speed * C
    out = np.stack([p[..., 0] + c * along - s * across, p[..., 1] + s * along + c * across], axis=-1)
    return out, speed + acceleration * tau, psi + x


def _anchors(start, velocity, pieces):
    """Position, speed and (unwrapped) course at the start of every piece, (R, P, 2), (R, P), (R, P)."""
    t0, t1, rate, acc, _ = pieces
    R, P = t0.shape
    p = np.empty((R, P, 2))
    speed = np.empty((R, P))
    psi = np.empty((R, P))
    p[:, 0] = start
    speed[:, 0] = np.hypot(velocity[:, 0], velocity[:, 1])
    psi[:, 0] = np.arctan2(velocity[:, 1], velocity[:, 0])
    prev = np.zeros(R)                        # piece 0 is anchored at t = 0
    for j in range(1, P):
        finite = np.isfinite(t0[:, j])
        tau = np.where(finite, t0[:, j] - prev, 0.0)
        q, s, a = advance(p[:, j - 1], speed[:, j - 1], psi[:, j - 1], tau, rate[:, j - 1], acc[:, j - 1])
        p[:, j], speed[:, j], psi[:, j] = q, s, a
        prev = np.where(finite, t0[:, j], prev)
    return p, speed, psi


def manoeuvring_motion(start, velocity, manoeuvres: Manoeuvres, times):
    """Positions, velocities, course and labels of manoeuvring passages at ``times``.

    Parameters
    ----------
    start, velocity : ndarray, shape (R, 2)
        Position (m) and velocity (m/s) at t = 0.
    manoeuvres : Manoeuvres
        The R passages' schedule.
    times : ndarray, shape (K,) or (R, K)
        Times, s (before 0: the initial straight motion extended backwards).

    Returns
    -------
    positions, velocities : ndarray, shape (R, K, 2)
    course : ndarray, shape (R, K)
        Course angle :math:`\\psi`, unwrapped (continuous; its change since t = 0 is the hull's turn), rad.
    label : ndarray of int8, shape (R, K)
        :data:`STRAIGHT`, :data:`TURN` or :data:`SPEED_CHANGE`.
    """
    start = np.asarray(start, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    R = start.shape[0]
    t = np.broadcast_to(np.asarray(times, dtype=float), (R, np.shape(times)[-1]))
    pieces = manoeuvres.pieces()
    t0, t1, rate, acc, lab = pieces
    p_a, s_a, psi_a = _anchors(start, velocity, pieces)
    # piece 0, before the first manoeuvre: the straight motion as it always was (cv_positions' expression)
    pos = start[:, None, :] + t[..., None] * velocity[:, None, :]
    vel = np.broadcast_to(velocity[:, None, :], pos.shape).copy()
    course = np.broadcast_to(psi_a[:, :1], t.shape).copy()
    label = np.zeros(t.shape, dtype=np.int8)
    for j in range(1, t0.shape[1]):
        active = (t >= t0[:, j, None]) & (t < t1[:, j, None])
        if not active.any():
            continue
        anchor = np.where(np.isfinite(t0[:, j]), t0[:, j], 0.0)[:, None]
        q, s, a = advance(p_a[:, j, None], s_a[:, j, None], psi_a[:, j, None], t - anchor, rate[:, j, None],
                          acc[:, j, None])
        pos = np.where(active[..., None], q, pos)
        vel = np.where(active[..., None], s[..., None] * np.stack([np.cos(a), np.sin(a)], axis=-1), vel)
        course = np.where(active, a, course)
        label = np.where(active, lab[:, j, None], label)
    return pos, vel, course, label


def turned_moment(m0, turn, body_fixed_share):
    """Magnetic moment after the hull turned by ``turn`` (rad, (...)) since the moment was ``m0`` (..., 3):
    :math:`(1-\\sigma) m_0 + \\sigma R_z(\\Delta\\psi) m_0` (module equations), (..., 3)."""
    m0 = np.asarray(m0, dtype=float)
    c, s = np.cos(turn), np.sin(turn)
    sig = float(body_fixed_share)
    out = np.empty(np.broadcast_shapes(m0.shape, np.shape(turn) + (3,)))
    out[..., 0] = m0[..., 0] + sig * ((c - 1.0) * m0[..., 0] - s * m0[..., 1])
    out[..., 1] = m0[..., 1] + sig * (s * m0[..., 0] + (c - 1.0) * m0[..., 1])
    out[..., 2] = m0[..., 2]
    return out


def transition_jacobians(start, velocity, manoeuvres: Manoeuvres, times):
    """Jacobians of the true motion of the kinematic state ``(x, y, v_x, v_y)`` over every sampling
    interval, (R, K-1, 4, 4).

    Over ``[t_k, t_{k+1}]`` the motion is the composition of the pieces it overlaps, each of duration
    :math:`\\tau` starting at velocity :math:`v` (speed :math:`s`, direction :math:`u`):

    .. math:: F = \\begin{bmatrix} I & B + \\frac{a\\tau^2}{2s} P \\\\ 0 & R(\\omega\\tau) + \\frac{a\\tau}{s} P
              \\end{bmatrix}, \\quad B = \\begin{bmatrix} S & -C \\\\ C & S\\end{bmatrix}, \\quad P = I - u u^T,

    (the coordinated turn with a known rate is linear; the along-track acceleration with a known ``a``
    turns with the velocity's direction, hence ``P``).  Without manoeuvres every interval gives the
    constant-velocity transition.  ``times`` (K,), s.
    """
    times = np.asarray(times, dtype=float)
    R = np.asarray(start).shape[0]
    lo, hi = times[:-1], times[1:]
    F = np.broadcast_to(np.eye(4), (R, lo.size, 4, 4)).copy()
    t0, t1, rate, acc, _ = manoeuvres.pieces()
    for j in range(t0.shape[1]):
        a0 = np.maximum(lo[None, :], t0[:, j, None])                   # (R, K-1)
        tau = np.clip(np.minimum(hi[None, :], t1[:, j, None]) - a0, 0.0, None)
        if not np.any(tau > 0):
            continue
        _, v, _, _ = manoeuvring_motion(start, velocity, manoeuvres, np.where(tau > 0, a0, lo[None, :]))
        w = rate[:, j, None]
        a = acc[:, j, None]
        x = w * tau
        S = tau * np.sinc(x / np.pi)
        C = 0.5 * x * tau * np.sinc(x / (2 * np.pi)) ** 2
        s = np.hypot(v[..., 0], v[..., 1])
        u = v / np.where(s > 0, s, 1.0)[..., None]
        P = np.eye(2) - u[..., :, None] * u[..., None, :]
        g = np.where(s > 0, a / np.where(s > 0, s, 1.0), 0.0)[..., None, None]
        Fj = np.broadcast_to(np.eye(4), tau.shape + (4, 4)).copy()
        Fj[..., 0, 2], Fj[..., 0, 3], Fj[..., 1, 2], Fj[..., 1, 3] = S, -C, C, S
        Fj[..., 0:2, 2:4] += 0.5 * tau[..., None, None] ** 2 * g * P
        cw, sw = np.cos(x), np.sin(x)
        Fj[..., 2, 2], Fj[..., 2, 3], Fj[..., 3, 2], Fj[..., 3, 3] = cw, -sw, sw, cw
        Fj[..., 2:4, 2:4] += tau[..., None, None] * g * P
        F = Fj @ F
    return F
