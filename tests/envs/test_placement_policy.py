"""The placement agent's per-candidate policy: one scoring network shared by every candidate."""

import numpy as np
import pytest

pytest.importorskip("sb3_contrib")

import torch  # noqa: E402

from shipsense.envs.placement_policy import CandidateExtractor, candidate_count, grid_places  # noqa: E402
from shipsense.envs.sites import SITE_FEATURES  # noqa: E402


def test_the_candidate_count_follows_the_observation_layout_and_a_foreign_one_is_refused():
    assert candidate_count(SITE_FEATURES + 3 * 81 + 1) == 81
    with pytest.raises(ValueError, match="not ArrayDesign-v1's"):
        candidate_count(SITE_FEATURES + 3 * 81)


def test_grid_places_are_the_candidates_positions_scaled():
    from shipsense.design.placement import grid_candidates

    hw = 30.0
    xy = grid_candidates([(-hw, -hw), (hw, -hw), (hw, hw), (-hw, hw)], 7.5, 0.0)[:, :2]
    np.testing.assert_allclose(grid_places(len(xy)).numpy(), xy / hw, atol=1e-6)
    assert not grid_places(7).any()                                   # not a square grid: no places


def test_each_candidate_is_scored_by_the_same_network():
    """Permuting the candidates (their inputs and places together) permutes the logits the same way: no weight
    belongs to a position in the observation."""
    torch.manual_seed(0)
    n = 9
    ext = CandidateExtractor(SITE_FEATURES + 3 * n + 1, vf=[8])
    obs = torch.rand(3, SITE_FEATURES + 3 * n + 1)
    perm = torch.randperm(n)
    moved = obs.clone()
    for b in range(3):
        block = slice(SITE_FEATURES + b * n, SITE_FEATURES + (b + 1) * n)
        moved[:, block] = obs[:, block][:, perm]
    logits = ext.forward_actor(obs)
    ext.places = ext.places[perm]
    torch.testing.assert_close(ext.forward_actor(moved), logits[:, perm])
    assert ext.forward_critic(obs).shape == (3, 8) and logits.shape == (3, n)
