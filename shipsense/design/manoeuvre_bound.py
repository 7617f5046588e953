r"""The posterior CRLB of a manoeuvring passage, conditional on its true manoeuvre sequence.

A passage that turns and changes speed is a switching system; its reference bound is the PCRLB conditional
on the true sequence of manoeuvres (the 'enumeration' bound of Hernandez, Ristic & Farina): the recursion of
Tichavský et al. along the true trajectory with each step's own transition,

.. math::  J_{k+1} = (Q_k + F_k J_k^{-1} F_k^T)^{-1} + H_{k+1}^T R^{-1} H_{k+1},

:math:`F_k` the Jacobian of the true motion over the step (:func:`~shipsense.physics.manoeuvre.transition_jacobians`:
the coordinated turn at the true rate, the along-track acceleration) and :math:`Q_k` the process noise of
the tracker's motion model.  The magnetic moment's transition follows the hull's turn: with the body-fixed
share :math:`\sigma` the moment at step :math:`k` is :math:`M_k m_0`,
:math:`M_k = (1-\sigma) I + \sigma R_z(\Delta\psi_k)`, so :math:`F^m_k = M_{k+1} M_k^{-1}` (a rotation and
scaling of the horizontal components, the identity for :math:`\sigma = 0`; where :math:`M_k` is singular,
:math:`\sigma = 1/2` half-way through a half turn, the identity is taken).  The electric height and dipole
are constant.  Without manoeuvres every :math:`F_k` is the constant-velocity transition and the bound is
:func:`~shipsense.design.fisher.pcrlb`'s.

References
----------
M. L. Hernandez, B. Ristic and A. Farina, "A performance bound for manoeuvring target tracking using best-fitting
Gaussian distributions", Proc. 8th Int. Conf. on Information Fusion, 2005 (and Hernandez, Ristic, Farina,
Sathyan, Kirubarajan, IEEE T-AES 42(4), 2006, for the enumeration bound of switching systems).
P. Tichavský, C. H. Muravchik and A. Nehorai, "Posterior Cramér–Rao bounds for discrete-time nonlinear
filtering", IEEE Trans. Signal Processing 46(5), 1998.
"""

from __future__ import annotations

import numpy as np

from shipsense.design.fisher import PassageMotion, measurement_information, pcrlb_from_information
from shipsense.physics.manoeuvre import STRAIGHT, Manoeuvres, manoeuvring_motion, transition_jacobians

SINGULAR = 1e-9
"""Below this :math:`|\\det M_k|^{1/2}` the moment's transition is taken as the identity."""


def manoeuvre_transitions(model, start, velocity, manoeuvres: Manoeuvres, times):
    """Transitions :math:`F_k` (R, K-1, n, n) of ``model``'s state along passages with known manoeuvres
    (internal units; the kinematic block and the moment's are unit-free maps, so SI and internal agree).

    Parameters
    ----------
    model : FieldModel
    start, velocity : ndarray, shape (R, 2)
        Position (m) and velocity (m/s) at t = 0.
    manoeuvres : Manoeuvres
    times : ndarray, shape (K,)
        Sample times, s.
    """
    F = np.broadcast_to(np.eye(model.n), (len(start), len(times) - 1, model.n, model.n)).copy()
    F[..., :4, :4] = transition_jacobians(start, velocity, manoeuvres, times)
    if "mx" in model.labels and manoeuvres.body_fixed_share > 0 and manoeuvres.any:
        i = model.labels.index("mx")
        course = manoeuvring_motion(start, velocity, manoeuvres, times)[2]
        sig = manoeuvres.body_fixed_share
        c = (1.0 - sig) + sig * np.exp(1j * (course - course[:, :1]))     # M_k on the horizontal plane
        ok = np.abs(c[:, :-1]) > SINGULAR
        r = np.where(ok, c[:, 1:] / np.where(ok, c[:, :-1], 1.0), 1.0)
        F[..., i, i], F[..., i, i + 1] = r.real, -r.imag
        F[..., i + 1, i], F[..., i + 1, i + 1] = r.imag, r.real
    return F


def conditional_pcrlb(model, states, J0, F, Q=None):
    """The PCRLB conditional on the true manoeuvres: one bound per passage (module equations).

    Parameters
    ----------
    model : FieldModel
    states : ndarray, shape (R, K, n)
        True states (internal units).
    J0 : ndarray, shape (n, n)
        Prior information at step 0.
    F : ndarray, shape (R, K-1, n, n)
        The true transitions (:func:`manoeuvre_transitions`).
    Q : ndarray, shape (n, n) or (R, K-1, n, n), optional
        Process noise of the tracker's motion model (default ``model.Q``).

    Returns
    -------
    bounds : ndarray, shape (R, K, n, n)
    """
    info = measurement_information(model, states, per_run=True)
    return pcrlb_from_information(model, info, J0, Q=Q, F=F)


def simulation_bound(model, sim, J0, Q=None):
    """:func:`conditional_pcrlb` of every passage of a :class:`~shipsense.simulator.Simulation` (its truth
    and manoeuvre schedule), (R, K, n, n) in internal units."""
    truth = np.asarray(sim.truth)
    F = manoeuvre_transitions(model, truth[:, 0, 0:2], truth[:, 0, 2:4], sim.manoeuvres, sim.times)
    return conditional_pcrlb(model, model.to_internal(model.state_from_truth(truth)), J0, F, Q=Q)


def passage_motion(model, x0, manoeuvres: Manoeuvres, times):
    r"""The known motion of passages starting at ``x0`` with a manoeuvre schedule, for their Fisher
    information about the initial state (:func:`~shipsense.design.fisher.passage_fim`): the true states
    (:func:`~shipsense.simulator.manoeuvring_truth`) and :math:`\Phi_k = F_{k-1} \cdots F_0`, the product of
    the true transitions (:func:`manoeuvre_transitions`); None when no passage manoeuvres (the constant
    velocity then is their motion).

    Parameters
    ----------
    model : FieldModel
    x0 : ndarray, shape (R, 9)
        Initial truth states (:data:`~shipsense.simulator.STATE_LABELS`, SI), as
        :func:`~shipsense.simulator.sample_manoeuvring_passages` draws them.
    manoeuvres : Manoeuvres
    times : ndarray, shape (K,)
        Sample times, s.

    Returns
    -------
    PassageMotion or None
        Internal units, (R, K, n) and (R, K, n, n).
    """
    if not manoeuvres.any:
        return None
    from shipsense.simulator import manoeuvring_truth

    x0 = np.asarray(x0, dtype=float)
    truth = manoeuvring_truth(x0, manoeuvres, times)[0]
    F = manoeuvre_transitions(model, x0[:, 0:2], x0[:, 2:4], manoeuvres, times)
    phi = np.empty((len(x0), len(times), model.n, model.n))
    phi[:, 0] = np.eye(model.n)
    for k in range(1, len(times)):
        phi[:, k] = F[:, k - 1] @ phi[:, k - 1]
    return PassageMotion(model.to_internal(model.state_from_truth(truth)), phi,
                         np.any(manoeuvres.kind != STRAIGHT, axis=1))
