"""Generated bad input for the recording reader and the command line: each ends in the project's error (a
RecordingError naming the file and line; exit 2 with one ``shipsense CMD: error:`` line), never a traceback,
within a time limit.  (The scenario schema has its own, tests/test_config_fuzz.py.)"""

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from shipsense import load_scenario
from shipsense.cli import main
from shipsense.recording import RecordingError, read_recording

S2 = load_scenario("S2")
CELL = st.one_of(st.sampled_from(["", "nan", "inf", "-inf", "1e308", "-0", "M1", "bx", "abc", "0x10", "1,2",
                                  '"', "\u00e9", " 1 ", "1e-9", "0.5", "0.500000001"]),
                 st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=12))


@settings(derandomize=True, max_examples=500, deadline=2000,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.tuples(CELL, st.sampled_from(["M1", "M2", "A1", "X"]), st.sampled_from(["bx", "by", "e"]),
                               CELL), min_size=1, max_size=6))
def test_a_generated_recording_reads_or_names_its_line(tmp_path_factory, rows):
    path = tmp_path_factory.mktemp("rec") / "r.csv"
    path.write_text("time,sensor,channel,value\n" + "\n".join(",".join(r) for r in rows) + "\n", encoding="utf-8")
    try:
        times, y = read_recording(path, S2)
    except RecordingError as err:
        assert str(err).startswith(str(path)) and "\n" not in str(err)
    else:
        assert times.ndim == 1 and y.shape == (times.size, S2.array().n_channels)
        assert all(math.isfinite(t) for t in times) and not any(math.isinf(v) for v in y.ravel())


BAD_NUMBER = st.one_of(st.sampled_from(["-1", "0", "1e9", "abc", "", "nan", "1.5", "-0", "99999999999999999999",
                                        "--", "1_000"]), st.integers(max_value=0).map(str), st.text(max_size=8))
COMMANDS = {
    "simulate": (["simulate", "S2"], ["--runs", "--seed"]),
    "check": (["check", "S1-P2"], ["--passages", "--seed"]),
    "design": (["design", "S1-P2", "--k", "3"], ["--passages", "--seed"]),
    "train": (["train", "scheduling"], ["--timesteps", "--seed"]),
    "reproduce": (["reproduce", "S0"], ["--runs", "--seed"]),
    "sweep": (["sweep", "x.toml", "--out", "d"], ["--workers"]),
}


@settings(derandomize=True, max_examples=300, deadline=2000,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(command=st.sampled_from(sorted(COMMANDS)), data=st.data())
def test_a_bad_count_or_seed_on_any_command_is_exit_2_before_any_work(command, data, capsys):
    base, flags = COMMANDS[command]
    flag = data.draw(st.sampled_from(flags))
    value = data.draw(BAD_NUMBER.filter(lambda v: not _valid(command, flag, v)))
    assert main([*base, f"{flag}={value}"]) == 2
    err = capsys.readouterr().err
    assert "shipsense" in err and "error:" in err and flag in err and "Traceback" not in err


def _valid(command, flag, text):
    """Whether a value would be accepted (those would start real work: the strategy leaves them out)."""
    try:
        v = int(text)
    except ValueError:
        return False
    lo = {"--runs": 2 if command == "reproduce" else 1, "--workers": 0, "--seed": 0}.get(flag, 1)
    return lo <= v <= (2**63 - 1 if flag == "--seed" else 10**6)


ENV_ARGS = {"PassageV1Env": {"k": (1, 3, True), "energy_cost": (0.0, 1e6, False),
                             "error_scale": (1e-6, 1e6, False)},
            "ArrayDesignEnv": {"k": (1, 81, True), "half_width": (0.5, 1e5, False),
                               "passages": (1, 10_000, True), "shaping": (0.0, 1e6, False)},
            "SiteDesignEnv": {"k": (1, 81, True), "half_width": (5.0, 1e4, False), "passages": (1, 1000, True),
                              "stride": (1, 100, True), "ambiguity_penalty": (0.0, 1e6, False),
                              "max_steps": (4, 10**6, True)}}
BAD_ARG = st.one_of(st.sampled_from(["x", "", "3", None, True, [], math.nan, math.inf, -math.inf, -1, 0, 0.0, 2.5,
                                     1e308, -1e308, 10**30]), st.floats(allow_nan=True), st.integers())


def _accepted(value, lo, hi, integer):
    if isinstance(value, bool) or value is None or isinstance(value, (str, list)):
        return False
    if integer and not isinstance(value, int):
        return False
    return math.isfinite(value) and lo <= value <= hi


@settings(derandomize=True, max_examples=200, deadline=5000)
@given(env=st.sampled_from(sorted(ENV_ARGS)), data=st.data())
def test_a_bad_environment_argument_is_one_error_naming_it(env, data):
    """The environments' constructor arguments: a bad one (a string, NaN, a float count, out of range) is one
    ValueError naming the argument, before any passage is simulated."""
    from shipsense.envs.array_design import ArrayDesignEnv
    from shipsense.envs.passage_v1 import PassageV1Env
    from shipsense.envs.site_design import SiteDesignEnv

    name = data.draw(st.sampled_from(sorted(ENV_ARGS[env])))
    lo, hi, integer = ENV_ARGS[env][name]
    value = data.draw(BAD_ARG.filter(lambda v: not _accepted(v, lo, hi, integer) and v is not None))
    cls = {"PassageV1Env": PassageV1Env, "ArrayDesignEnv": ArrayDesignEnv, "SiteDesignEnv": SiteDesignEnv}[env]
    try:
        cls(**{name: value})
    except ValueError as err:
        assert name in str(err), str(err)
    else:
        raise AssertionError(f"{env}({name}={value!r}) was accepted")
