"""The README runs as written: every Python block, in order, in one namespace (they build on each other), and
every shell block not marked ``<!-- long: reason -->`` (the marked ones -- fresh installs, a full sweep, a
cluster -- run with ``SHIPSENSE_README_LONG=1``, from the repository's root)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCK = re.compile(r"(<!-- long: (?P<why>[^>]*) -->\n)?```(?P<lang>\w*)\n(?P<body>.*?)```", re.S)
BLOCKS = [(m["lang"], m["body"], m["why"]) for m in BLOCK.finditer(README.read_text())]
LONG = os.environ.get("SHIPSENSE_README_LONG") == "1"


def test_the_python_blocks_run_in_order(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {}
    python = [body for lang, body, _ in BLOCKS if lang == "python"]
    assert len(python) >= 5
    for i, body in enumerate(python):
        exec(compile(body, f"README.md python block {i + 1}", "exec"), namespace)


@pytest.mark.parametrize("body,why", [(b, w) for lang, b, w in BLOCKS if lang == "bash"],
                         ids=lambda v: v.splitlines()[0][:40] if isinstance(v, str) and "\n" in v else None)
def test_the_shell_blocks_run(body, why):
    if why and not LONG:
        pytest.skip(f"long ({why}): set SHIPSENSE_README_LONG=1")
    # the interpreter's own bin folder first: its ``shipsense`` command, even when the venv is not activated
    path = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])
    subprocess.run(["bash", "-e", "-c", body], cwd=README.parent, check=True, env={**os.environ, "PATH": path})


def test_the_set_up_commands_agree_on_torch():
    """The two set-up commands: either both pin torch or neither does (CI installs its build first)."""
    setup = [b for lang, b, _ in BLOCKS if lang == "bash" and "python3 -m venv" in b]
    assert len(setup) == 2
    assert len({"torch==" in b for b in setup}) == 1
