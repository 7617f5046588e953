"""ArrayDesign-v1: checkers, masks through gym.make, order-free reward, sites under the seed, the time limit,
the vector version and its seeds, baselines, bad arguments."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs.site_design import SiteDesignEnv, SiteDesignVectorEnv
from shipsense.envs.sites import SITE_FEATURES

# one depth (S1-P2's own 15 m: the electric kernel is shared with the other tests), 25 candidates, 3 sensors
SITE = {"heading_deg": 30.0, "heading_spread_deg": 10.0, "cpa_m": [-10.0, 10.0], "speed_mps": [5.0, 8.0],
        "p_Am": [80.0, 160.0], "water_depth_m": 15.0}
SMALL = {"k": 3, "half_width": 20.0, "spacing": 10.0, "passages": 2, "site": SITE}


def grid_index(env, x, y):
    xy = env.unwrapped.core.xy
    return int(np.argmin(np.hypot(xy[:, 0] - x, xy[:, 1] - y)))


def test_gymnasium_checker_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(SiteDesignEnv(**SMALL), skip_render_check=True)
    assert not caught, [str(w.message) for w in caught]


def test_stable_baselines_checker_passes():
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(SiteDesignEnv(**SMALL), warn=True)


def test_masks_reach_through_gym_make_and_follow_exclusions_and_picks():
    site = {**SITE, "exclusions": [[0.0, 0.0, 12.0]]}
    env = gym.make("shipsense/ArrayDesignSmall-v1", passages=2, site=site)
    env.reset(seed=0)
    masks = env.get_wrapper_attr("action_masks")
    xy = env.unwrapped.core.xy
    inside = np.hypot(*xy.T) <= 12.0
    assert inside.sum() == 5 and np.array_equal(masks(), ~inside)        # the centre and its 4 neighbours
    a = int(np.flatnonzero(masks())[0])
    env.step(a)
    assert not masks()[a] and masks().sum() == 25 - 5 - 1


def test_reward_depends_on_the_set_not_the_order():
    env = SiteDesignEnv(**SMALL)
    picks = [grid_index(env, -20, -20), grid_index(env, 20, -10), grid_index(env, 0, 20)]
    rewards = []
    for order in (picks, picks[::-1], [picks[1], picks[0], picks[2]]):
        env.reset(seed=3)
        for a in order:
            _, r, term, _, info = env.step(a)
        assert term
        rewards.append(r)
    assert rewards[0] == pytest.approx(rewards[1], rel=1e-12) == pytest.approx(rewards[2], rel=1e-12)
    m = info["episode_metrics"]
    assert rewards[0] == pytest.approx(m["score"] - 2.0 * m["ambiguous"])
    assert m["score"] == pytest.approx(env.score(picks))


def test_a_collinear_layout_is_ambiguous_and_penalised_a_triangle_is_not():
    env = SiteDesignEnv(**SMALL)

    def play(points):
        env.reset(seed=0)
        for x, y in points:
            _, r, _, _, info = env.step(grid_index(env, x, y))
        return r, info["episode_metrics"]

    r_line, line = play([(0, -20), (0, 0), (0, 20)])
    r_tri, tri = play([(-20, -20), (20, -20), (0, 20)])
    assert line["ambiguous"] == 1.0 and tri["ambiguous"] == 0.0
    assert r_line == pytest.approx(line["score"] - 2.0)


def test_more_sensors_never_lower_the_score():
    """The D-criterion is monotone: adding a sensor adds positive semi-definite information."""
    env = SiteDesignEnv(**SMALL)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        s = list(rng.choice(25, 4, replace=False))
        assert env.score(s) >= env.score(s[:3]) >= env.score(s[:2]) >= env.score(s[:1]) >= env.score([]) == 0.0


def test_the_seed_draws_the_site_and_the_same_seed_the_same_site():
    env = SiteDesignEnv(k=3, half_width=20.0, spacing=10.0, passages=1, stride=8)
    a, _ = env.reset(seed=0)
    site_a = env.core.sites[0]
    b, _ = env.reset(seed=1)
    c, _ = env.reset(seed=0)
    assert env.core.sites[0] == site_a and np.array_equal(a, c)
    assert not np.allclose(a[:SITE_FEATURES], b[:SITE_FEATURES])


def test_invalid_picks_are_penalised_no_ops_and_the_time_limit_ends_the_episode():
    env = SiteDesignEnv(**{**SMALL, "max_steps": 4})
    env.reset(seed=0)
    _, r, term, trunc, info = env.step(0)
    assert r == 0.0 and not info["invalid"]
    for _ in range(2):
        _, r, term, trunc, info = env.step(0)                   # taken: a penalised no-op
        assert info["invalid"] and info["placed"] == 1 and not term
    _, r, term, trunc, info = env.step(0)                        # the 4th step: the limit
    assert trunc and not term and info["episode_metrics"]["ambiguous"] == 1.0
    assert r == pytest.approx(-1.0 + env.score([0]) - 2.0)
    with pytest.raises(RuntimeError):
        env.step(1)


def test_greedy_picks_the_largest_gain_of_the_observation_and_gains_are_score_rises():
    env = SiteDesignEnv(**SMALL)
    obs, _ = env.reset(seed=0)
    N = env.core.N
    greedy = env.baseline("greedy")
    chosen = []
    for _ in range(3):
        gain = obs[SITE_FEATURES + 2 * N:SITE_FEATURES + 3 * N]
        a = greedy(obs)
        assert a == int(np.argmax(gain)) and gain.max() == 1.0
        best = max(env.score(chosen + [i]) for i in np.flatnonzero(env.action_masks()))   # brute force
        assert env.score(chosen + [a]) == pytest.approx(best, rel=1e-12)
        chosen.append(a)
        obs, *_ = env.step(a)


def test_incremental_rewards_sum_to_the_terminal_reward():
    picks = [3, 17, 9]
    returns = {}
    for mode in ("terminal", "incremental"):
        env = SiteDesignEnv(**SMALL, reward=mode)
        env.reset(seed=4)
        rewards = [env.step(a)[1] for a in [3, 3] + picks[1:]]          # one invalid pick in between
        returns[mode] = sum(rewards)
        if mode == "incremental":
            assert rewards[0] == pytest.approx(env.score([3])) and rewards[1] == -1.0
    assert returns["incremental"] == pytest.approx(returns["terminal"], rel=1e-9)


def test_greedy_beats_random_on_average():
    env = SiteDesignEnv(**SMALL)
    greedy, rand = env.baseline("greedy"), env.baseline("random")
    scores = {"greedy": [], "random": []}
    for seed in range(6):
        for name, policy in (("greedy", greedy), ("random", rand)):
            obs, _ = env.reset(seed=seed)
            while True:
                obs, _, term, trunc, info = env.step(policy(obs))
                if term or trunc:
                    break
            scores[name].append(info["episode_metrics"]["score"])
    assert np.mean(scores["greedy"]) > np.mean(scores["random"])


def test_an_unknown_baseline_is_refused_naming_the_offered_ones():
    with pytest.raises(ValueError, match="'round-robin' is not offered.*random, greedy, convex"):
        SiteDesignEnv(**SMALL).baseline("round-robin")


@pytest.mark.parametrize("kwargs, name", [
    ({"k": 26}, "k"), ({"k": 0}, "k"), ({"ambiguity_penalty": -1.0}, "ambiguity_penalty"),
    ({"passages": 0}, "passages"), ({"spacing": "x"}, "spacing"), ({"ambiguity": "some"}, "ambiguity"),
    ({"max_steps": 2}, "max_steps"), ({"site": {**SITE, "exclusions": [[0.0, 0.0, 100.0]]}}, "site"),
    ({"site": {**SITE, "depth": 3}}, "site"), ({"site": {**SITE, "speed_mps": [8.0, 5.0]}}, "site.speed_mps"),
    ({"render_mode": "text"}, "render_mode"), ({"reward": "dense"}, "reward"),
    ({"scenario": "no-such-scenario"}, "scenario"),
])
def test_bad_arguments_raise_one_value_error_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SiteDesignEnv(**{**SMALL, **kwargs})


def test_vector_env_seeds_match_the_single_env_and_autoreset_in_the_next_step():
    kwargs = {**SMALL, "site": None, "passages": 1, "stride": 8}
    venv = gym.make_vec("shipsense/ArrayDesignSmall-v1", num_envs=2, vectorization_mode="vector_entry_point",
                        passages=1, stride=8)
    single = SiteDesignEnv(**kwargs)
    obs, _ = venv.reset(seed=[7, 11])
    for i, s in enumerate((7, 11)):
        assert np.array_equal(obs[i], single.reset(seed=s)[0])
    obs, _ = venv.reset(seed=5)                                          # an int seeds environment i with 5 + i
    assert np.array_equal(obs[1], single.reset(seed=6)[0])
    for step in range(3):
        masks = venv.unwrapped.action_masks()
        obs, rewards, term, trunc, info = venv.step(np.array([np.flatnonzero(m)[step] for m in masks]))
    assert term.all() and info["_episode_metrics"].all() and info["episode_metrics"]["_score"].all()
    assert rewards == pytest.approx(info["episode_metrics"]["score"] - 2.0 * info["episode_metrics"]["ambiguous"])
    assert (obs[:, -1] == 1.0).all() and info["_layout"].all() and len(info["layout"][0]) == 3   # the last obs
    assert "_placed" in info and info["_placed"].all()
    obs, rewards, term, trunc, info = venv.step(np.zeros(2, dtype=int))    # the next step resets, actions ignored
    assert (obs[:, -1] == 0).all() and (rewards == 0).all() and not (term | trunc).any()
    assert not info["_placed"].any() and "episode_metrics" not in info
    single.reset(seed=6)
    assert np.array_equal(obs[1], single.reset()[0])                   # its next site, from its own stream


def test_render_draws_the_site():
    env = SiteDesignEnv(**SMALL, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(0)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8 and img.std() > 0


def test_vector_env_refuses_a_wrong_number_of_seeds():
    venv = SiteDesignVectorEnv(2, **SMALL)
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2, 3])


def test_vector_baselines_act_as_the_single_envs_and_random_picks_free_candidates_reproducibly():
    """The native vector env's batched greedy picks, in each environment, what the single env's greedy picks on
    the same site; its random one only free candidates, the same ones under the same seed."""
    kwargs = {**SMALL, "site": None, "passages": 1, "stride": 8}
    venv = SiteDesignVectorEnv(2, **kwargs)
    single = SiteDesignEnv(**kwargs)
    greedy = venv.baseline("greedy")
    venv.reset(seed=[3, 8])
    picks = []
    for _ in range(3):
        a = greedy()
        picks.append(a)
        venv.step(a)
    for i, s in enumerate((3, 8)):
        single.reset(seed=s)
        act = single.baseline("greedy")
        for a in picks:
            assert act(None) == a[i]
            single.step(act(None))
    draws = []
    for _ in range(2):
        venv.reset(seed=[3, 8])
        rand, seq = venv.baseline("random", seed=4), []
        for _ in range(3):
            masks = venv.action_masks()
            a = rand()
            assert masks[np.arange(2), a].all()
            seq.append(a)
            venv.step(a)
        draws.append(np.array(seq))
    assert np.array_equal(*draws)
    with pytest.raises(ValueError, match="'convex' is not offered.*random, greedy"):
        venv.baseline("convex")


def test_exhaustive_finds_the_best_layout_and_greedy_never_beats_it():
    import itertools

    env = SiteDesignEnv(**SMALL)
    for seed in range(2):
        scores = {}
        for name in ("exhaustive", "greedy"):
            act = env.baseline(name)
            obs, _ = env.reset(seed=seed)
            while True:
                obs, _, term, trunc, info = env.step(act(obs))
                if term or trunc:
                    break
            scores[name] = info["episode_metrics"]["score"]
        free = np.flatnonzero(env.core.free[0])                       # (a fixed site: the same every episode)
        best = max(env.score(c) for c in itertools.combinations(free, 3))
        assert scores["exhaustive"] == pytest.approx(best, abs=1e-9) and scores["greedy"] <= best + 1e-9


def test_exhaustive_refuses_a_task_with_too_many_layouts():
    env = SiteDesignEnv(site=SITE, passages=1, stride=8)               # 4 of 81 candidates
    act = env.baseline("exhaustive")
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="policy exhaustive: 1,663,740 layouts"):
        act(obs)
