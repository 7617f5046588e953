"""Key numba's on-disk cache of the compiled kernels on everything they are compiled from.

numba caches a compiled function (``cache=True``) under a stamp of the file that defines it (a hash of its
contents), not of the files whose functions it inlines or whose constants it freezes (numba issue #8396):
after an edit of only ``shipsense/models/measurement.py``, or an upgrade that changed it, the filter steps
in ``fused.py`` that inline its measurement function would load stale machine code.  Each module with
compiled kernels ends with :func:`key_on_sources`, which replaces its kernels' stamp by a hash of the module
and of every package file it takes code or constants from (:data:`DEPENDS`, transitively), so that a change
in any of them rebuilds it.  The stamp is a private attribute of numba's cache
(``Dispatcher._cache._cache_file._source_stamp``, numba 0.5x-0.6x); a numba without it keeps its own
behaviour.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

DEPENDS = {
    "design/subsets.py": (),
    "design/information_gain.py": ("models/measurement.py", "trackers/linalg.py"),
    "envs/features.py": (),
    "envs/passage_v1.py": ("arguments.py", "design/information_gain.py", "envs/core_env.py", "envs/features.py",
                           "envs/prefetch.py", "simulator.py", "trackers/tracker/results.py"),
    "models/measurement.py": ("parallel.py", "physics/hed_kernel.py", "physics/kernels.py"),
    "physics/hed_kernel.py": (),
    "physics/kernels.py": ("physics/magnetic.py",),
    "trackers/bank/selection.py": (),
    "trackers/filters/kernels.py": ("models/measurement.py", "trackers/filters/core.py", "trackers/linalg.py"),
    "trackers/fit/lm.py": ("models/measurement.py", "parallel.py", "trackers/linalg.py"),
    "trackers/init/detection.py": (),
    "trackers/init/distinct.py": (),
    "trackers/init/grid.py": ("models/measurement.py", "models/transitions.py", "trackers/fit/least_squares.py",
                              "trackers/init/distinct.py", "trackers/linalg.py"),
    "trackers/linalg.py": (),
    "trackers/tracker/consistency.py": (),
    "trackers/tracker/restarts.py": ("models/transitions.py", "trackers/fit/least_squares.py",
                                     "trackers/init/detection.py", "trackers/init/distinct.py",
                                     "trackers/init/global_init.py", "trackers/init/window_fits.py"),
    "trackers/tracker/step.py": ("models/measurement.py", "parallel.py", "trackers/bank/selection.py",
                                 "trackers/filters/fused.py", "trackers/filters/kernels.py",
                                 "trackers/init/detection.py", "trackers/tracker/consistency.py"),
}
"""Each file with compiled kernels (relative to the package) and the package modules it imports at module
level (tests/test_numba_cache.py checks this against the sources)."""

PACKAGE = Path(__file__).parent


def sources(name, depends=DEPENDS):
    """``name`` and every file its compiled code may take from: its imports, and theirs if they are kernel
    files too (sorted)."""
    seen, todo = set(), [name]
    while todo:
        f = todo.pop()
        if f not in seen:
            seen.add(f)
            todo.extend(depends.get(f, ()))
    return sorted(seen)


def sources_digest(name, root=PACKAGE, depends=DEPENDS):
    """SHA-256 of the names and contents of :func:`sources` of ``name``."""
    h = hashlib.sha256()
    for f in sources(name, depends):
        h.update(f.encode() + b"\0" + (Path(root) / f).read_bytes() + b"\0")
    return h.digest()


def key_on_sources(namespace, root=PACKAGE, depends=DEPENDS):
    """Stamp the cached kernels defined in a module (its ``globals()``, and the values of its dicts: kernels
    a factory made) with :func:`sources_digest`; returns how many.  Call it at the end of the module, after
    its kernels are defined (numba reads the stamp when it first loads or saves a kernel, at its first call)."""
    name = Path(namespace["__file__"]).resolve().relative_to(Path(root).resolve()).as_posix()
    digest = sources_digest(name, root, depends)
    count = 0
    found = []
    for obj in list(namespace.values()):   # the module's kernels, also those it keeps in a dict (kernel factories)
        found.extend(obj.values() if isinstance(obj, dict) else (obj,))
    for obj in found:
        cache_file = getattr(getattr(obj, "_cache", None), "_cache_file", None)
        func = getattr(obj, "py_func", None)
        if cache_file is None or func is None or func.__module__ != namespace["__name__"]:
            continue
        if hasattr(cache_file, "_source_stamp"):
            cache_file._source_stamp = digest
            count += 1
    return count


def specialised(func, name, jit, **names):
    """``jit`` of a copy of ``func`` named ``name`` whose globals also hold ``names`` (the kernels it calls,
    chosen per copy: e.g. one filter's update loop).

    This is how a kernel is specialised per filter and still cached by numba: numba keys a cached function on its
    qualified name, bytecode and closure, and a kernel held in the closure (a dispatcher, pickled with an id of its
    process) would never match the cache; a global of the copy is not part of the key.  Each copy has its own
    qualified name, because numba names a cached function's file and its machine code's symbol after it (with a
    counter that restarts in every process): two copies of one name compiled in different processes would link to
    each other's code.  The only place the package builds functions this way.
    """
    from types import FunctionType

    copy = FunctionType(func.__code__, {**func.__globals__, **names}, func.__name__, func.__defaults__,
                        func.__closure__)
    copy.__qualname__ = name
    return jit(copy)


def cached(*dispatchers):
    """Whether each of ``dispatchers`` has compiled code on disk for its current sources (its first call then
    loads it instead of compiling); False when numba's cache cannot tell."""
    for d in dispatchers:
        try:
            if not d._cache._cache_file._load_index():
                return False
        except Exception:   # noqa: BLE001 - a numba without these internals, an unreadable cache: unknown
            return False
    return True
