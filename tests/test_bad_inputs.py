"""Bad inputs at the command line, as a user gives them: each ends in one line naming the input, exit code 2, and
nothing written (no output folder, no hidden staging folder)."""

import json
import textwrap

import pytest

from shipsense.cli import main


def refused(argv, capsys, *fragments, out=None):
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and "internal error" not in err and "Traceback" not in err, err
    for f in fragments:
        assert f in err, err
    if out is not None:
        assert not out.exists() and not list(out.parent.glob(f".{out.name}.*")), list(out.parent.iterdir())
    return err


# -- design --candidates --------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, fragments", [
    ("x,y,z\n0,0,-15\n10,0,2\n20,0,-15\n", ["row 3", "above the sea surface"]),
    ("x,y,z\n0,0,-15\n10,0,-30\n20,0,-15\n", ["row 3", "below the seabed"]),
    ("x,y\n5,5\n5,5\n5,5\n5,5\n", ["row 3", "coincides with row 2"]),           # every candidate at one point
    ("x,y\n0,0\n10,nan\n20,0\n", ["row 3, y", "finite"]),
    ("x,y\n0,0\n10,five\n20,0\n", ["row 3, y", "expected a number"]),
    ("x,y,cost\n0,0,1\n10,0,-1\n20,0,1\n", ["row 3, cost", ">= 0"]),
    ("x,y\n0,0\n1e300,0\n20,0\n", ["row 3, x", "physical range"]),
    ("a,b\n0,0\n", ["header with x,y"]),
    ("x,y\n", ["no candidates"]),
])
def test_a_bad_candidate_csv_is_one_line(tmp_path, capsys, text, fragments):
    cands = tmp_path / "cands.csv"
    cands.write_text(text)
    out = tmp_path / "design"
    refused(["design", "S1-P2", "--k", "3", "--candidates", cands, "--out", out], capsys, "cands.csv", *fragments,
            out=out)


REGION = """
[candidates]
polygon = [[-20.0, -20.0], [20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]]
spacing = 10.0
"""


@pytest.mark.parametrize("old, new, fragments", [
    ("spacing = 10.0", "spacing = 0.0", ["candidates.spacing", "> 0"]),
    ("spacing = 10.0", 'spacing = "5 m"', ["candidates.spacing", "expected a number", "'5 m'"]),
    ("[-20.0, -20.0], [20.0, -20.0]", "[-20.0, -20.0], [nan, -20.0]", ["candidates.polygon[1]", "finite"]),
    ("spacing = 10.0", "spacing = 1e-4", ["candidates.spacing", "grid points"]),
    ("spacing = 10.0", "spacing = 10.0\nz = 3.0", ["candidates.z", "0"]),
    ("spacing = 10.0", "spacing = 10.0\nz = -40.0", ["below the seabed"]),
    ("spacing = 10.0", "spacing = 10.0\nexclusions = [[0.0, 0.0, -5.0]]", ["candidates.exclusions[0]"]),
    ("spacing = 10.0", "spacing = 10.0\nmin_spacing = -1.0", ["candidates.min_spacing"]),
    ("spacing = 10.0", "spacing = 10.0\nspcing = 1.0", ["candidates.spcing", "unknown field"]),
    ("spacing = 10.0", "spacing = 10.0\nexclusions = [[0.0, 0.0, 100.0]]", ["no grid point"]),
    ("[-20.0, -20.0], [20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]", "[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]",
     ["candidates", "no area"]),
])
def test_a_bad_candidate_region_is_one_line(tmp_path, capsys, old, new, fragments):
    assert old in REGION
    cands = tmp_path / "region.toml"
    cands.write_text(REGION.replace(old, new))
    out = tmp_path / "design"
    refused(["design", "S1-P2", "--k", "3", "--candidates", cands, "--out", out], capsys, "region.toml", *fragments,
            out=out)


def test_a_valid_candidate_region_loads_with_the_template_height():
    import tempfile
    from pathlib import Path

    from shipsense import load_scenario
    from shipsense.design.candidates import load_candidates

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "region.toml"
        path.write_text(REGION)
        pts, costs = load_candidates(path, load_scenario("S1-P2"))
    assert pts.shape == (25, 3) and costs is None and (pts[:, 2] == -15.0).all()


# -- scenarios ----------------------------------------------------------------------------------------------


@pytest.fixture
def s0_text():
    from pathlib import Path

    import shipsense

    return (Path(shipsense.__file__).parent / "scenarios" / "S0.toml").read_text()


@pytest.mark.parametrize("command", ["simulate", "track"])
@pytest.mark.parametrize("old, new, fragments", [
    ("speed = [4.0, 10.0]", "speed = [4.0, 1e308]", ["prior.speed", "100 m/s"]),
    ("levels = [1e6, 1e7, 1e8]", "levels = [1e308]", ["tracker.bank.levels[0]", "1e+12"]),
    ("noise_var = 8e-18", "noise_var = 1e-320", ["sensors[0].noise_var", "at least 1e-30"]),
])
def test_a_scenario_value_that_overflowed_is_one_line(tmp_path, capsys, s0_text, command, old, new, fragments):
    assert old in s0_text
    path = tmp_path / "s0.toml"
    path.write_text(s0_text.replace(old, new))
    out = tmp_path / ("run.npz" if command == "simulate" else "run")
    refused([command, path, "--out", out], capsys, "s0.toml", *fragments, out=out)


def test_a_nearly_insulating_seabed_is_refused_not_a_simulation_that_never_ends(tmp_path, capsys):
    from pathlib import Path

    import shipsense

    text = (Path(shipsense.__file__).parent / "scenarios" / "S1-P2.toml").read_text()
    path = tmp_path / "p2.toml"
    path.write_text(text.replace("sigma_seabed = 0.04", "sigma_seabed = 1e-308"))
    out = tmp_path / "run.npz"
    refused(["simulate", path, "--out", out], capsys, "p2.toml", "sigma_seabed", "ratio", out=out)


def test_a_thousand_vector_magnetometers_are_refused_by_the_work_budget(tmp_path, capsys):
    """The tracker's work grows with the channels (the innovation covariance is channels x channels): the
    budget's estimate counts them, so 1,000 vector magnetometers are refused before any work."""
    sensors = "".join(textwrap.dedent(f"""
        [[sensors]]
        id = "M{i}"
        type = "magnetometer"
        kind = "vector"
        position = [{(i % 40) * 5.0 - 100.0}, {(i // 40) * 5.0 - 60.0}, -20.0]
        noise_var = 8e-18
        """) for i in range(1000))
    path = tmp_path / "many.toml"
    path.write_text('name = "many"\nperiod = 0.1\nsteps = 300\n' + sensors + textwrap.dedent("""
        [passage]
        start = [-140.0, -70.0]
        velocity = [6.0, 6.0]
        z = 0.0
        moment = [8e7, 2e7, 4e7]
        """))
    out = tmp_path / "run"
    refused(["track", path, "--out", out], capsys, "--max-", out=out)


# -- check ----------------------------------------------------------------------------------------------------
def test_check_labels_its_text_output_by_file_as_the_json_does(tmp_path, capsys):
    """Two files holding scenarios of one name are told apart in the text output, as in the JSON and JUnit."""
    from pathlib import Path

    import shipsense

    text = (Path(shipsense.__file__).parent / "scenarios" / "S1-P2.toml").read_text()
    paths = []
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        paths.append(tmp_path / name / "layout.toml")
        paths[-1].write_text(text)
    assert main(["check", *map(str, paths), "--passages", "2"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if not line.startswith(" ")]
    assert [line.split(": ")[0] for line in lines] == [str(p) for p in paths]
    assert main(["check", str(paths[0]), "--passages", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["layout"] == str(paths[0])
