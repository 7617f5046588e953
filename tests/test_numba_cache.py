"""numba's cache of the compiled kernels follows every file they are compiled from (numba keys it on the
defining file alone)."""

import ast
import importlib.util
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import shipsense
from shipsense import numba_cache

PACKAGE = Path(shipsense.__file__).parent


def _independent_imports(path):
    """The package files a file imports at module level, by a whole-file parse and Python's own module finder
    (not numba_cache's scan): each ``from shipsense.X import names`` at the top level gives X's file, or for a
    package the submodules it names and, for any other name, its ``__init__.py``."""
    found = set()
    for node in ast.parse(path.read_text()).body:
        if not (isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0]
                == "shipsense"):
            continue
        spec = importlib.util.find_spec(node.module)
        if spec.submodule_search_locations is None:         # a module
            found.add(Path(spec.origin))
            continue
        for alias in node.names:
            sub = importlib.util.find_spec(f"{node.module}.{alias.name}") if (
                Path(spec.origin).parent / f"{alias.name}.py").exists() or (
                Path(spec.origin).parent / alias.name / "__init__.py").exists() else None
            found.add(Path(sub.origin) if sub is not None else Path(spec.origin))
    return {p.resolve().relative_to(PACKAGE.resolve()).as_posix() for p in found}


def test_the_derived_import_graph_equals_a_whole_file_parse_of_every_package_file():
    """numba_cache reads only the import statements at the start of a line (cheap at import); for every file of
    the package it finds exactly what a whole-file parse of its top-level statements finds."""
    files = sorted(p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py"))
    assert len(files) > 100
    for name in files:
        assert set(numba_cache.imports_of(name)) == _independent_imports(PACKAGE / name), name


def test_every_file_that_compiles_keys_its_caches_and_follows_its_imports_transitively():
    """The kernel files are exactly the files that compile with numba, each ending with ``key_on_sources``; a
    kernel's sources are its imports' closure: the filters' kernels take the dipole's constant from
    physics/magnetic.py through two files they do not import themselves."""
    compiles = {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
                if "njit(" in p.read_text() or "@loop_jit" in p.read_text()}
    assert set(numba_cache.kernel_files()) == compiles
    graph = {name: _independent_imports(PACKAGE / name) for name in
             {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")}}
    for name in compiles:
        closure, todo = set(), [name]
        while todo:
            f = todo.pop()
            if f not in closure:
                closure.add(f)
                todo.extend(graph[f])
        assert numba_cache.sources(name) == sorted(closure), name
    filters = numba_cache.sources("trackers/filters/kernels.py")
    assert "physics/magnetic.py" not in numba_cache.imports_of("trackers/filters/kernels.py")
    assert {"models/measurement.py", "physics/kernels.py", "physics/magnetic.py"} <= set(filters)
    assert "envs/site_design.py" not in filters


def test_an_edited_dependency_changes_the_digest_and_an_unrelated_file_does_not(tmp_path):
    """On a copy of the package: editing a file a kernel module takes from (directly or through another file)
    changes its digest, editing an unrelated file does not; a new import is followed without any table."""
    root = tmp_path / "shipsense"
    shutil.copytree(PACKAGE, root, ignore=shutil.ignore_patterns("__pycache__"))
    name = "trackers/filters/kernels.py"

    def digest():
        return numba_cache.sources_digest(name, root)

    def append(rel, text):
        with open(root / rel, "a") as f:
            f.write(text)

    first = digest()
    assert first == numba_cache.sources_digest(name)                 # the copy's, as the package's
    append("cli/parser.py", "\n# an unrelated edit\n")
    append("envs/sites.py", "\n# not imported yet\n")
    assert digest() == first
    append("physics/magnetic.py", "\nMU0_OVER_4PI = 1e-7\n")          # two imports away
    second = digest()
    assert second != first
    append("trackers/filters/kernels.py", "\nfrom shipsense.envs.sites import Site  # noqa\n")
    third = digest()
    assert third != second and "envs/sites.py" in numba_cache.sources(name, root)
    append("envs/sites.py", "\n# now imported\n")
    assert digest() != third


USER_PACKAGE = {
    "__init__.py": "",
    "dep.py": """
        from numba import njit


        @njit(inline="always")
        def g():
            return {}
        """,
    "other.py": "X = 1\n",
    "user.py": """
        import sys

        from numba import njit

        from shipsense import numba_cache
        from userpkg.dep import g


        @njit(cache=True)
        def f():
            return g()


        if sys.argv[1] == "keyed":
            numba_cache.key_on_sources(globals(), root=sys.argv[2])
        print(f(), sum(f.stats.cache_hits.values()))
        """,
}


def test_an_edit_of_an_inlined_file_rebuilds_the_kernel_and_an_unrelated_edit_reloads_it(tmp_path):
    """A kernel inlining another file's function, cached, then that file edited: numba alone loads the stale
    kernel (the control); keyed on its sources, the kernel is rebuilt.  Keyed, a second run and a run after an
    edit of a file the kernel does not import load it from the cache."""
    pkg = tmp_path / "userpkg"

    def run(mode):
        path = os.pathsep.join([str(tmp_path), str(PACKAGE.parent)])
        out = subprocess.run([sys.executable, str(pkg / "user.py"), mode, str(pkg)], cwd=tmp_path,
                             capture_output=True, text=True, check=True, env=dict(os.environ, PYTHONPATH=path))
        value, hits = out.stdout.split()
        return value, int(hits)

    for mode in ("plain", "keyed"):
        shutil.rmtree(pkg, ignore_errors=True)
        pkg.mkdir()
        for name, text in USER_PACKAGE.items():
            (pkg / name).write_text(textwrap.dedent(text).format(1.0) if name == "dep.py" else textwrap.dedent(text))
        assert run(mode) == ("1.0", 0)                                    # compiled
        assert run(mode) == ("1.0", 1)                                    # loaded
        (pkg / "dep.py").write_text(textwrap.dedent(USER_PACKAGE["dep.py"]).format(2.0))
        assert run(mode) == (("1.0", 1) if mode == "plain" else ("2.0", 0))
        if mode == "keyed":
            (pkg / "other.py").write_text("X = 2\n")
            assert run(mode) == ("2.0", 1)


def test_a_package_kernel_reloads_from_the_cache_in_a_new_process(tmp_path):
    """The stamp is the same in every process (a digest of the sources): a kernel compiled in one process is
    loaded, not compiled, by the next."""
    code = ("import numpy as np; from shipsense import numba_cache; from shipsense.trackers.linalg import "
            "solve_in_place as k; before = numba_cache.cached(k); x = np.ones(2); k(2.0 * np.eye(2), x, 2); "
            "print(before, x[0], sum(k.stats.cache_hits.values()))")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    outs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                           cwd=PACKAGE.parent).stdout.split() for _ in range(2)]
    assert outs == [["False", "0.5", "0"], ["True", "0.5", "1"]]


def test_the_package_kernels_are_keyed_on_their_sources():
    from shipsense.models import measurement
    from shipsense.trackers.filters import kernels as fused

    digest = numba_cache.sources_digest("trackers/filters/kernels.py")
    kernels = [*fused.UPDATE_KERNELS.values(), *fused.UPDATE_LOOPS.values()]      # one per filter, and loops
    assert len(kernels) == 12 and all(k._cache._cache_file._source_stamp == digest for k in kernels)
    assert measurement.batch_kernel._cache._cache_file._source_stamp != digest      # its own sources


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
