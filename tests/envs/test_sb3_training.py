"""The SB3 adapter over gymnasium vector envs (both autoreset modes), the evaluation and the training entry
points: short learns, refusals, bad arguments."""

import json
from contextlib import contextmanager

import gymnasium as gym
import numpy as np
import pytest

import shipsense  # noqa: F401  (registers the environments)
from shipsense.envs.evaluation import evaluate, load_policy

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

SITE = {"heading_deg": 30.0, "heading_spread_deg": 10.0, "cpa_m": [-10.0, 10.0], "speed_mps": [5.0, 8.0],
        "p_Am": [80.0, 160.0], "water_depth_m": 15.0}
KW = {"passages": 2, "site": SITE}
SMALL_ID = "shipsense/ArrayDesignSmall-v1"


def _native(n=2):
    return gym.make_vec(SMALL_ID, num_envs=n, vectorization_mode="vector_entry_point", **KW)


def _sync_next_step(n=2):
    return gym.make_vec(SMALL_ID, num_envs=n, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}, **KW)


def _sync_same_step(n=2):
    return gym.make_vec(SMALL_ID, num_envs=n, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}, **KW)


@pytest.mark.parametrize("make", [_native, _sync_next_step, _sync_same_step],
                         ids=["native-next-step", "sync-next-step", "sync-same-step"])
def test_adapter_hands_sb3_the_terminal_observation_and_the_reset_one(make):
    from shipsense.envs.sb3 import VectorEnvAdapter

    venv = VectorEnvAdapter(make())
    venv.seed(0)
    obs = venv.reset()
    assert obs.shape == (2,) + venv.observation_space.shape
    for step in range(3):
        masks = np.stack(venv.env_method("action_masks"))
        assert masks.shape == (2, 25)
        obs, rewards, dones, infos = venv.step(np.array([np.flatnonzero(m)[step] for m in masks]))
    assert dones.all() and rewards.dtype == np.float32
    for i in range(2):
        final = infos[i]["terminal_observation"]
        assert final[-1] == 1.0 and obs[i][-1] == 0.0                  # last obs: 3 of 3 placed; new episode: 0
        assert set(infos[i]["episode_metrics"]) == {"score", "ambiguous", "seconds"}
        assert rewards[i] == pytest.approx(infos[i]["episode_metrics"]["score"]
                                           - 2.0 * infos[i]["episode_metrics"]["ambiguous"], rel=1e-6)
        assert infos[i]["TimeLimit.truncated"] is False
    assert venv.has_attr("action_masks") and not venv.has_attr("no_such_thing")


def test_maskable_ppo_and_ppo_learn_through_the_adapter():
    from sb3_contrib import MaskablePPO
    from stable_baselines3 import PPO

    from shipsense.envs.sb3 import VectorEnvAdapter

    for algo, make in ((MaskablePPO, _native), (PPO, _sync_next_step)):
        venv = VectorEnvAdapter(make())
        model = algo("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
        model.learn(256)
        assert model.num_timesteps >= 256


def test_evaluate_refuses_a_policy_the_env_does_not_offer():
    with pytest.raises(ValueError, match="'round-robin' is not offered by shipsense/ArrayDesignSmall-v1 "
                                         r"\(offered: random, greedy, convex"):
        evaluate(SMALL_ID, "round-robin", 2, 0, KW)
    with pytest.raises(ValueError, match="policy: no model file"):
        evaluate(SMALL_ID, "missing.zip", 2, 0, KW)


@pytest.mark.parametrize("args, name", [
    (("shipsense/Nope-v0", "random", 2, 0), "env_id"), ((SMALL_ID, "random", 0, 0), "episodes"),
    ((SMALL_ID, "random", 2, -1), "seed"), ((SMALL_ID, "random", 2, 0, {"k": 99}), "k"),
])
def test_evaluate_names_a_bad_argument(args, name):
    with pytest.raises(ValueError, match=name):
        evaluate(*args)


def test_evaluate_averages_the_episodes_it_ran():
    r = evaluate(SMALL_ID, "greedy", 3, 5, KW)
    env = gym.make(SMALL_ID, **KW)
    act = load_policy(env, "greedy")
    scores = []
    for e in range(3):
        obs, _ = env.reset(seed=5 + e)
        while True:
            obs, reward, term, trunc, info = env.step(act(obs))
            if term or trunc:
                break
        scores.append(info["episode_metrics"]["score"])
    assert r["metrics"]["score"]["mean"] == pytest.approx(np.mean(scores))
    assert r["metrics"]["score"]["stderr"] == pytest.approx(np.std(scores, ddof=1) / np.sqrt(3))
    assert r["length"] == 3.0


@pytest.mark.parametrize("kwargs, name", [
    ({"kind": "walking"}, "kind"), ({"env_id": "shipsense/Nope-v0"}, "env_id"), ({"timesteps": 10}, "timesteps"),
    ({"n_envs": 0}, "n_envs"), ({"eval_episodes": 0}, "eval_episodes"), ({"env_kwargs": [1]}, "env_kwargs"),
    ({"shaping": -1.0}, "shaping"), ({"shaping": 1.0}, "shaping"),   # ArrayDesign-v1 declares no potential
    ({"imitate_policy": "convex"}, "imitate_policy"),                  # not offered by the vector env
    ({"kind": "scheduling", "env_id": "shipsense/PassageEasy-v1", "imitate_policy": "oracle"}, "imitate_policy"),
])
def test_train_names_a_bad_argument(kwargs, name, tmp_path):
    from shipsense.envs.training import train

    with pytest.raises(ValueError, match=name):
        train(**{"kind": "placement", "timesteps": 128, "out": tmp_path, **kwargs})
    assert not any(tmp_path.iterdir())


def test_train_placement_then_evaluate_the_saved_model(tmp_path, capsys):
    from shipsense.cli import main

    out = tmp_path / "run"
    assert main(["--quiet", "train", "placement", "--env", SMALL_ID, "--env-kwargs", json.dumps(KW),
                 "--timesteps", "128", "--n-envs", "2", "--eval-every", "64", "--eval-episodes", "2",
                 "--imitation-steps", "96", "--out", str(out)]) == 0
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["algorithm"] == "MaskablePPO" and summary["timesteps"] >= 128
    assert summary["imitate_policy"] == "greedy" and 0.0 <= summary["imitation_agreement"] <= 1.0   # the default
    assert [p["timesteps"] for p in json.loads((out / "learning_curve.json").read_text())][:2] == [0, 64]
    for name in ("best_model.zip", "final_model.zip", "learning_curve.png"):
        assert (out / name).is_file()
    assert any((out / "tensorboard").rglob("events.out.tfevents*"))
    capsys.readouterr()
    assert main(["--quiet", "evaluate", SMALL_ID, "--env-kwargs", json.dumps(KW), "--policy",
                 str(out / "best_model.zip"), "--episodes", "2", "--seed", "0", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["episodes"] == 2 and result["metrics"]["ambiguous"]["mean"] in (0.0, 0.5, 1.0)
    assert main(["evaluate", SMALL_ID, "--policy", "round-robin"]) == 2
    assert "round-robin" in capsys.readouterr().err


def test_a_random_baseline_is_reproducible_under_the_evaluations_seed():
    """Passage-v1's random policy has its own generator: evaluate seeds it, so the same seed gives the same
    episodes and another seed other ones."""
    env_id, kw = "shipsense/PassageEasy-v1", {"overrides": {"steps": 40}}
    a, b = (evaluate(env_id, "random", 2, 11, kw)["per_episode"]["return"] for _ in range(2))
    c = evaluate(env_id, "random", 2, 12, kw)["per_episode"]["return"]
    assert a == b and c[0] != a[0]


def test_potential_shaping_adds_what_telescopes_to_minus_the_first_potential():
    """Per episode, the discounted sum of the shaping terms is ``-coef * phi(first observation)`` whatever the
    actions (Ng et al. 1999): the shaping cannot change which policy is best.  The unshaped reward is kept."""
    from shipsense.envs.passage_v1 import PassageV1VectorEnv, observation_potential
    from shipsense.envs.sb3 import PotentialShaping, VectorEnvAdapter

    coef, gamma, n = 0.7, 0.9, 2
    venv = PotentialShaping(VectorEnvAdapter(PassageV1VectorEnv(num_envs=n, scenario="S2",
                                                                overrides={"steps": 45})), observation_potential,
                            coef, gamma)
    venv.seed(3)
    obs = venv.reset()
    first, acc, disc = observation_potential(obs), np.zeros(n), np.ones(n)
    rng, checked = np.random.default_rng(0), 0
    for _ in range(40):
        obs, rewards, dones, infos = venv.step(rng.integers(0, 4, n))
        shaping = rewards - np.array([info["unshaped_reward"] for info in infos], dtype=np.float32)
        acc += disc * shaping
        disc *= gamma
        for i in np.flatnonzero(dones):
            assert acc[i] == pytest.approx(-coef * first[i], rel=1e-4, abs=1e-4)
            checked += 1
            first[i], acc[i], disc[i] = observation_potential(obs[i]), 0.0, 1.0
    assert checked >= n


def test_train_scheduling_from_a_cloned_greedy_scores_the_clone_first(tmp_path):
    from shipsense.cli import main

    out = tmp_path / "bc"
    assert main(["--quiet", "train", "scheduling", "--env", "shipsense/PassageEasy-v1", "--env-kwargs",
                 json.dumps({"overrides": {"steps": 50}}), "--timesteps", "64", "--n-envs", "2",
                 "--imitate", "greedy", "--imitation-steps", "200", "--shaping", "1", "--eval-episodes", "1",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["imitate_policy"] == "greedy" and summary["imitation_steps"] == 200 and summary["shaping"] == 1.0
    assert 0.0 <= summary["imitation_agreement"] <= 1.0
    assert json.loads((out / "learning_curve.json").read_text())[0]["timesteps"] == 0   # the clone, scored
    assert set(summary["held_out_baselines"]) == {"greedy", "round-robin", "random"}     # drawn on the curve
    # the agent's own time is the run's without the cloning and the held-out episodes
    assert summary["imitation_seconds"] > 0 and summary["evaluation_seconds"] > 0
    own = summary["timesteps"] / summary["own_frames_per_second"]
    assert own + summary["imitation_seconds"] + summary["evaluation_seconds"] == pytest.approx(summary["seconds"])


def test_unbatch_info_gives_each_environment_its_entries_as_python_values():
    from shipsense.envs.sb3 import unbatch_info

    info = {"error": np.array([1.5, 2.5, 3.5]), "_error": np.array([True, False, True]),
            "status": np.array([2, 3, 1], dtype=np.int8), "truth": np.arange(6.0).reshape(3, 2),
            "episode_metrics": {"return": np.array([0.0, -1.0, 0.0]), "_return": np.array([False, True, False])},
            "_episode_metrics": np.array([False, True, False])}
    out = unbatch_info(info, 3)
    assert out[0]["error"] == 1.5 and type(out[0]["error"]) is float and "error" not in out[1]
    assert out[1]["status"] == 3 and type(out[1]["status"]) is int      # (no mask: every environment)
    np.testing.assert_array_equal(out[2]["truth"], [4.0, 5.0])
    assert out[1]["episode_metrics"] == {"return": -1.0} and "episode_metrics" not in out[0]


@pytest.mark.parametrize("args, flag", [(["--imitate", "oracle"], "--imitate"), (["--shaping", "-2"], "--shaping")])
def test_train_names_the_flag_of_a_bad_value(args, flag, tmp_path, capsys):
    from shipsense.cli import main

    assert main(["train", "scheduling", "--env", "shipsense/PassageEasy-v1", "--timesteps", "64", *args,
                 "--out", str(tmp_path / "x")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines()
           if "compiling the numerical kernels" not in line]          # (a cold cache's notice comes first)
    assert len(err) == 1 and f"error: {flag}" in err[0] and not (tmp_path / "x").exists()


def test_train_and_evaluate_say_when_the_tracker_will_compile(monkeypatch, capsys, tmp_path):
    """The Passage environments run the tracker: with its kernels not yet on disk, ``train`` (scheduling) and
    ``evaluate`` say so first (their times then include compiling); ArrayDesign's do not."""
    from shipsense.cli import main
    from shipsense.cli import track as tracking

    monkeypatch.setattr(tracking, "first_use_notice", lambda filter_name=None: "compiling the numerical kernels")
    assert main(["--quiet", "evaluate", "shipsense/PassageEasy-v1", "--policy", "random", "--episodes", "1"]) == 0
    assert "evaluate: compiling the numerical kernels" in capsys.readouterr().err
    assert main(["--quiet", "evaluate", SMALL_ID, "--env-kwargs", json.dumps(KW), "--policy", "random",
                 "--episodes", "1"]) == 0
    assert "compiling" not in capsys.readouterr().err
    assert main(["train", "scheduling", "--env", "shipsense/PassageEasy-v1", "--timesteps", "64", "--imitate",
                 "oracle", "--out", str(tmp_path / "x")]) == 2
    assert capsys.readouterr().err.startswith("train: compiling the numerical kernels\n")


def test_training_defaults_are_the_measured_best_where_the_environment_allows_them():
    from shipsense.envs.training import training_defaults

    assert training_defaults("scheduling", "shipsense/Passage-v1") == (1.0, "greedy")
    assert training_defaults("scheduling", "shipsense/Passage-v1", 0.0, "none") == (0.0, None)
    assert training_defaults("scheduling", "shipsense/ArrayDesign-v0") == (0.0, None)   # no potential, no greedy
    assert training_defaults("placement", "shipsense/ArrayDesign-v1") == (0.0, "greedy")
    assert training_defaults("placement", "shipsense/ArrayDesign-v0") == (0.0, None)    # no baselines
    assert training_defaults("placement", "shipsense/ArrayDesign-v1", imitate_policy="none") == (0.0, None)


def test_a_cloned_maskable_policy_picks_the_teachers_action_within_the_masks():
    """Behaviour cloning of MaskablePPO: before it the policy agrees with greedy by chance, after it on most
    steps of sites it never saw (other seeds), and its picks, under the masks, are always free candidates."""
    from sb3_contrib import MaskablePPO

    from shipsense.envs.sb3 import VectorEnvAdapter
    from shipsense.envs.training import POLICY_KWARGS, agent_policy, imitate

    native = _native(4)
    venv = VectorEnvAdapter(native)
    venv.seed(0)
    model = MaskablePPO(agent_policy(SMALL_ID), venv, policy_kwargs=POLICY_KWARGS, seed=0, device="cpu")
    env = gym.make(SMALL_ID, **KW)
    greedy = load_policy(env, "greedy")

    def agreement():
        same = total = 0
        for s in range(100, 112):
            obs, _ = env.reset(seed=s)
            while True:
                masks = env.unwrapped.action_masks()
                a, want = int(model.predict(obs, action_masks=masks, deterministic=True)[0]), greedy(obs)
                assert masks[a]
                same, total = same + (a == want), total + 1
                obs, _, term, trunc, _ = env.step(want)          # along the teacher's episode
                if term or trunc:
                    break
        return same / total

    before = agreement()
    trained = imitate(model, venv, native.unwrapped.baseline("greedy"), 600, epochs=80, batch_size=64)
    after = agreement()
    assert before < 0.5 and trained > 0.75 and after > 0.6, (before, trained, after)   # (ties: near-equal gains)



def test_train_scheduling_clones_the_rollout_planner_on_a_passage_vector_env(tmp_path):
    """``--imitate rollout``: the teacher is the rollout planner deciding for every environment of the vector
    env's core (an environment whose passage just ended gets greedy's action, the step before its autoreset);
    the clone is scored first, as greedy's is."""
    from shipsense.cli import main

    out = tmp_path / "bc"
    assert main(["--quiet", "train", "scheduling", "--env", "shipsense/Passage-v2", "--env-kwargs",
                 json.dumps({"overrides": {"steps": 40}}), "--timesteps", "64", "--n-envs", "2",
                 "--imitate", "rollout", "--imitation-steps", "80", "--eval-episodes", "1",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["imitate_policy"] == "rollout" and 0.0 <= summary["imitation_agreement"] <= 1.0
    assert json.loads((out / "learning_curve.json").read_text())[0]["timesteps"] == 0


@contextmanager
def passage_v2_pair(steps, seed):
    """Two native Passage-v2 environments of ``steps`` samples, reset with ``seed``: (vector env, its core)."""
    venv = gym.make_vec("shipsense/Passage-v2", num_envs=2, vectorization_mode="vector_entry_point",
                        overrides={"steps": steps})
    try:
        venv.reset(seed=seed)
        yield venv, venv.unwrapped.core
    finally:
        venv.close()


def test_the_rollout_teacher_decides_as_the_rollout_planner_for_each_environment():
    from shipsense.envs.planning import Rollout
    from shipsense.envs.training import imitation_teacher

    with passage_v2_pair(40, 11) as (venv, core):
        teacher = imitation_teacher(venv, "shipsense/Passage-v2", "rollout", seed=3)
        planner = Rollout(core, seed=3)
        assert teacher(None).tolist() == [planner.decide(0), planner.decide(1)]   # (the same draws, in order)
        core.k[1] = core.K - 1                                    # a passage over: greedy's, no rollout
        assert teacher(None)[1] == core.greedy_actions()[1]
        with pytest.raises(ValueError, match="imitate_policy"):
            imitation_teacher(venv, "shipsense/Passage-v2", "greedy-threshold", seed=0)


def test_the_hindsight_teacher_replays_each_environment_s_own_plan():
    """``--imitate hindsight``: environment ``e`` of a vector env follows the schedule planned for its own passage
    at its first step (the single environment's planner on environment ``e``'s problem)."""
    from shipsense.envs.planning import Hindsight, ScheduleCosts, plan_schedule
    from shipsense.envs.training import imitation_teacher

    with passage_v2_pair(60, 5) as (venv, core):
        teacher = imitation_teacher(venv, "shipsense/Passage-v2", "hindsight", seed=0)
        plans = []
        for e in range(2):
            info0, J, Ainv = Hindsight(core).problem(e)
            plans.append(plan_schedule(info0, J, Ainv, core.subsets, core.energy_cost, core.error_scale, beam=256,
                                       costs=ScheduleCosts.of(core, e))[0])
        assert min(len(p) for p in plans) > 3 and plans[0].tolist() != plans[1].tolist()   # two passages, two plans
        taken = [[], []]
        for _ in range(3):
            actions = teacher(None)
            for e in range(2):
                taken[e].append(int(actions[e]))
            venv.step(actions)
        assert taken == [plans[0][:3].tolist(), plans[1][:3].tolist()]
