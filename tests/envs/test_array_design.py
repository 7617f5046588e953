"""ArrayDesign-v0: checkers, k placements then terminated, masks and invalid picks."""

import warnings

import numpy as np
import pytest

from shipsense.envs.array_design import ArrayDesignEnv

SMALL = {"half_width": 20.0, "spacing": 10.0, "passages": 3, "check_ambiguity": False}


def test_gymnasium_checker_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(ArrayDesignEnv(**SMALL), skip_render_check=True)
    assert not caught, [str(w.message) for w in caught]


def test_stable_baselines_checker_passes():
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(ArrayDesignEnv(**SMALL), warn=True)


def test_k_placements_then_terminated_with_the_verdict():
    env = ArrayDesignEnv(**{**SMALL, "check_ambiguity": True})
    obs, _ = env.reset(seed=0)
    assert env.action_masks().all() and obs[-1] == 0
    _, r, term, _, info = env.step(0)
    assert not term and r == 0.0 and not env.action_masks()[0]
    _, r, term, _, info = env.step(0)                        # occupied: a penalised no-op
    assert r == -1.0 and info["invalid"] and not term and info["placed"] == 1
    env.step(12)
    _, r, term, _, info = env.step(24)
    assert term and info["placed"] == 3
    assert info["verdict"] in ("observable", "ambiguous", "degenerate")
    assert r == pytest.approx(info["convergence_rate"] - min(info["trmse_m"] / 100.0, 1.0))
    with pytest.raises(RuntimeError):
        env.step(5)


def test_collinear_layout_scores_below_a_triangle():
    env = ArrayDesignEnv(**SMALL)
    pos = env.candidates[:, :2] - env.centre

    def score(points):
        env.reset(seed=0)
        r = 0.0
        for p in points:
            r = env.step(int(np.argmin(np.hypot(*(pos - p).T))))[1]
        return r

    line = score([(0, -20), (0, 0), (0, 20)])
    triangle = score([(-20, -20), (20, -20), (0, 20)])
    assert triangle > line


def test_continuous_mode_snaps_to_free_candidates():
    env = ArrayDesignEnv(**{**SMALL, "continuous": True})
    env.reset(seed=0)
    env.step(np.array([0.0, 0.0], dtype=np.float32))
    env.step(np.array([0.0, 0.0], dtype=np.float32))           # the same spot: the nearest free one
    assert len(set(env.chosen)) == 2


def test_information_gain_shaping_rewards_every_placement():
    env = ArrayDesignEnv(**{**SMALL, "shaping": 0.1})
    env.reset(seed=0)
    _, r1, *_ = env.step(0)
    _, r2, *_ = env.step(24)
    assert r1 > 0 and r2 > 0        # adding a sensor never removes information
