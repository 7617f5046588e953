"""The placement agent's policy: one shared scoring network applied to every candidate (:class:`CandidatePolicy`).

ArrayDesign-v1's observation (:mod:`shipsense.envs.site_design`) holds, per candidate ``i`` of the ``N`` on the
square grid, whether it is free of exclusions ``f_i``, whether a sensor stands there ``p_i`` and its gain if
placed next ``g_i`` (divided by the largest), after the site's features ``s`` (10) and before the fraction of the
sensors placed ``c``.  A flat network has to learn one logit per candidate from all ``3 N + 11`` inputs; cloned
from greedy it learns the training sites by heart rather than greedy's rule.  Here the logit of candidate ``i``
is one small network ``h`` of that candidate's own inputs and the shared ones,

.. math::

    \\ell_i = h(g_i, f_i, p_i, u_i, v_i, s, c), \\qquad i = 1 \\dots N,

with ``(u_i, v_i)`` the candidate's place on the grid scaled to [-1, 1] (row-major, as
:func:`~shipsense.design.placement.grid_candidates` orders them): the same weights score every candidate, so a
rule learned at one place holds at all (greedy is ``h = g_i``), and the masks then keep the free ones.  The value
is the usual multi-layer perceptron of the whole observation (``net_arch["vf"]``).  Requires the ``rl`` extra
(sb3-contrib).
"""

from __future__ import annotations

import math

import torch
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from torch import nn

from shipsense.envs.sites import SITE_FEATURES

CANDIDATE_HIDDEN = (64, 64)
"""Hidden layers of the per-candidate scoring network ``h``."""
PER_CANDIDATE = 5
"""Inputs of ``h`` that belong to the candidate: its gain, free and placed flags and its grid place (u, v)."""


def candidate_count(obs_dim):
    """The number of candidates ``N`` of an ArrayDesign-v1 observation of ``obs_dim`` entries
    (``SITE_FEATURES + 3 N + 1``); a ``ValueError`` when the size does not fit that layout."""
    n, rest = divmod(int(obs_dim) - SITE_FEATURES - 1, 3)
    if rest or n < 1:
        raise ValueError(f"an observation of {obs_dim} entries is not ArrayDesign-v1's ({SITE_FEATURES} + 3 N + 1)")
    return n


def grid_places(n):
    """The (n, 2) grid places (u, v) in [-1, 1] of ``n`` candidates on a square row-major grid (zeros when ``n`` is
    not a square)."""
    side = math.isqrt(n)
    if side * side != n or side < 2:
        return torch.zeros(n, 2)
    i = torch.arange(n)
    return torch.stack([i % side, i // side], dim=1).float() * (2.0 / (side - 1)) - 1.0


class CandidateExtractor(nn.Module):
    """The policy's latent: the ``N`` candidates' logits ``l_i`` (:mod:`shipsense.envs.placement_policy`); the
    value's: a multi-layer perceptron of the observation with hidden layers ``vf`` (``activation_fn``)."""

    def __init__(self, obs_dim, vf, activation_fn=nn.Tanh):
        super().__init__()
        self.n = candidate_count(obs_dim)
        self.register_buffer("places", grid_places(self.n))
        layers, width = [], PER_CANDIDATE + SITE_FEATURES + 1
        for h in CANDIDATE_HIDDEN:
            layers += [nn.Linear(width, h), activation_fn()]
            width = h
        self.score = nn.Sequential(*layers, nn.Linear(width, 1))
        layers, width = [], obs_dim
        for h in vf:
            layers += [nn.Linear(width, h), activation_fn()]
            width = h
        self.value = nn.Sequential(*layers)
        self.latent_dim_pi, self.latent_dim_vf = self.n, width

    def forward_actor(self, obs):
        """Logits (B, N) of observations (B, obs_dim)."""
        n, s = self.n, SITE_FEATURES
        free, placed, gain = obs[:, s:s + n], obs[:, s + n:s + 2 * n], obs[:, s + 2 * n:s + 3 * n]
        shared = torch.cat([obs[:, :s], obs[:, -1:]], dim=1)                               # (B, s + 1)
        own = torch.stack([gain, free, placed], dim=2)                                     # (B, N, 3)
        places = self.places.expand(obs.shape[0], n, 2)
        x = torch.cat([own, places, shared[:, None, :].expand(-1, n, -1)], dim=2)        # (B, N, 5 + s + 1)
        return self.score(x).squeeze(-1)

    def forward_critic(self, obs):
        return self.value(obs)

    def forward(self, obs):
        return self.forward_actor(obs), self.forward_critic(obs)


class CandidatePolicy(MaskableActorCriticPolicy):
    """MaskablePPO's actor-critic with the per-candidate scores as the action logits (:class:`CandidateExtractor`;
    no further layer mixes the candidates) and the value of ``net_arch["vf"]`` (default 64, 64)."""

    def _build_mlp_extractor(self):
        arch = self.net_arch if isinstance(self.net_arch, dict) else {"vf": list(self.net_arch or [])}
        self.mlp_extractor = CandidateExtractor(self.features_dim, arch.get("vf", [64, 64]), self.activation_fn)

    def _build(self, lr_schedule):
        super()._build(lr_schedule)
        self.action_net = nn.Identity()              # the logits are the candidates' scores
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)


__all__ = ["CANDIDATE_HIDDEN", "PER_CANDIDATE", "CandidateExtractor", "CandidatePolicy", "candidate_count",
           "grid_places"]
