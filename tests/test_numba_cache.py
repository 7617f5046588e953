"""numba's cache of the compiled kernels follows every file they are compiled from (numba keys it on the
defining file alone)."""

import ast
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import shipsense
from shipsense import numba_cache

PACKAGE = Path(shipsense.__file__).parent


def _module_file(module):
    path = PACKAGE.parent / (module.replace(".", "/") + ".py")
    return path.relative_to(PACKAGE).as_posix() if path.exists() else None


def test_the_dependency_table_lists_every_kernel_file_and_its_imports():
    """Every package file that compiles with numba is in DEPENDS, with exactly the package modules it imports at
    module level (a new kernel file, or a new import in one, must be added), and keys its caches."""
    kernels = {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
               if "njit(" in p.read_text() or "@loop_jit" in p.read_text()}
    assert kernels == set(numba_cache.DEPENDS)
    for name in kernels:
        text = (PACKAGE / name).read_text()
        tree = ast.parse(text)
        imported = {_module_file(node.module) for node in tree.body
                    if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("shipsense.")}
        assert imported - {None} == set(numba_cache.DEPENDS[name]), name
        assert text.rstrip().splitlines()[-1].startswith("numba_cache.key_on_sources(globals())"), name


def test_the_package_kernels_are_keyed_on_their_sources():
    from shipsense.models import measurement
    from shipsense.trackers.filters import kernels as fused

    digest = numba_cache.sources_digest("trackers/filters/kernels.py")
    kernels = [*fused.UPDATE_KERNELS.values(), *fused.UPDATE_LOOPS.values()]      # one per filter, and loops
    assert len(kernels) == 12 and all(k._cache._cache_file._source_stamp == digest for k in kernels)
    assert measurement.batch_kernel._cache._cache_file._source_stamp != digest      # its own sources


USER = """
import sys
from numba import njit
from shipsense import numba_cache
from dep import g


@njit(cache=True)
def f():
    return g()


if sys.argv[1] == "keyed":
    numba_cache.key_on_sources(globals(), root=sys.argv[2], depends={"user.py": ("dep.py",)})
print(f())
"""


def test_an_edit_of_an_inlined_file_rebuilds_the_kernel(tmp_path):
    """A kernel inlining another file's function, cached, then that file edited: numba alone loads the stale
    kernel (the control); keyed on its sources, the kernel is rebuilt."""
    (tmp_path / "user.py").write_text(USER)

    def run(mode):
        out = subprocess.run([sys.executable, "user.py", mode, str(tmp_path)], cwd=tmp_path, capture_output=True,
                             text=True, check=True)
        return out.stdout.strip()

    for mode in ("plain", "keyed"):
        for p in tmp_path.glob("__pycache__/*"):
            p.unlink()
        dep = textwrap.dedent("""
            from numba import njit


            @njit(inline="always")
            def g():
                return {}
            """)
        (tmp_path / "dep.py").write_text(dep.format(1.0))
        assert run(mode) == "1.0"
        (tmp_path / "dep.py").write_text(dep.format(2.0))
        assert run(mode) == ("1.0" if mode == "plain" else "2.0")


def test_the_first_use_notice_says_whether_the_tracker_will_compile(tmp_path):
    """``shipsense demo`` and ``track`` say when the tracker's kernels are about to compile: with an empty
    cache the notice is given; once a passage has been tracked (compiled or loaded), not."""
    from shipsense import simulate
    from shipsense.cli.track import first_use_notice
    from shipsense.trackers import Tracker

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", "from shipsense.cli.track import first_use_notice; "
                          "print(first_use_notice()); print(first_use_notice('ekf'))"], env=env, capture_output=True,
                         text=True, check=True)
    assert out.stdout.count("compiling the numerical kernels") == 2     # the tracker's UKF, and a --filter's
    sim = simulate("S2", runs=1, seed=3, random=True)
    Tracker("S2").track(sim.times, sim.measurements)
    assert first_use_notice() is None


def test_the_check_notice_says_whether_its_kernels_will_compile(tmp_path):
    """``shipsense check`` (a CI gate, often on a fresh machine) and ``design`` say when their kernels are about
    to compile: with an empty cache the notice is given; once a layout has been checked, not."""
    from shipsense.design.observability import check_scenario, first_use_notice

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", "from shipsense.design.observability import first_use_notice; "
                          "print(first_use_notice())"], env=env, capture_output=True, text=True, check=True)
    assert "compiling the least-squares and measurement kernels" in out.stdout and "NUMBA_CACHE_DIR" in out.stdout
    check_scenario("S0", passages=1)
    assert first_use_notice() is None


def test_a_specialised_copy_has_its_own_name_and_the_kernels_it_was_given():
    """numba_cache.specialised: each copy is named as asked and calls the kernel handed to it as a global."""
    from numba import njit

    one, two = njit(lambda: 1), njit(lambda: 2)

    def template():
        return _K()  # noqa: F821 - a global of each copy

    a = numba_cache.specialised(template, "_template_one", njit, _K=one)
    b = numba_cache.specialised(template, "_template_two", njit, _K=two)
    assert (a(), b()) == (1, 2)
    assert (a.py_func.__qualname__, b.py_func.__qualname__) == ("_template_one", "_template_two")
    assert "_K" not in template.__globals__
