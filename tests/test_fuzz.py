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


@settings(max_examples=500, deadline=2000, suppress_health_check=[HealthCheck.function_scoped_fixture])
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


@settings(max_examples=300, deadline=2000, suppress_health_check=[HealthCheck.function_scoped_fixture])
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
