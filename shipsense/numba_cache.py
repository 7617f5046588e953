"""Key numba's on-disk cache of the compiled kernels on everything they are compiled from.

numba caches a compiled function (``cache=True``) under a stamp of the file that defines it (a hash of its
contents), not of the files whose functions it inlines or whose constants it freezes (numba issue #8396):
after an edit of only ``shipsense/models/measurement.py``, or an upgrade that changed it, the filter steps
in ``fused.py`` that inline its measurement function would load stale machine code.  Each module with
compiled kernels ends with :func:`key_on_sources`, which replaces its kernels' stamp by a hash of the module
and of every package file it takes code or constants from (:func:`sources`: its module-level imports,
transitively, read from the sources at import), so that a change in any of them rebuilds it: moving a module or
adding an import needs no table.  The stamp is a private attribute of numba's cache
(``Dispatcher._cache._cache_file._source_stamp``, numba 0.5x-0.6x); a numba without it keeps its own
behaviour.
"""

from __future__ import annotations

import ast
import hashlib
import re
from pathlib import Path

PACKAGE = Path(__file__).parent

_IMPORT = re.compile(rb"^from[ \t]+\w+(?:\.\w+)*[ \t]+import[ \t]+(?:\([^)]*\)|[^\n]*)", re.M)
"""A module-level ``from X import ...`` statement: at the start of a line (a statement inside a function, a class
or an ``if`` is indented), its names on the line or in parentheses."""

_SCANNED: dict = {}
"""(path, mtime_ns, size) -> (the file's bytes, the package files it imports): each file is read and scanned
once per process while it is unchanged."""


def _scan(root, name):
    """The bytes of ``root/name`` and the package files (relative to ``root``) it imports at module level."""
    path = Path(root) / name
    st = path.stat()
    key = (str(path), st.st_mtime_ns, st.st_size)
    hit = _SCANNED.get(key)
    if hit is None:
        data = path.read_bytes()
        try:    # the import statements alone (parsing every file whole at import would cost a noticeable time)
            nodes = [ast.parse(m.group(0)).body[0] for m in _IMPORT.finditer(data)]
        except SyntaxError:    # (a statement the pattern cut short, e.g. continued by a backslash: the whole file)
            nodes = [n for n in ast.parse(data).body if isinstance(n, ast.ImportFrom)]
        found = set()
        for node in nodes:
            if node.level == 0 and node.module:
                found.update(module_files(node.module, [a.name for a in node.names], root))
        hit = _SCANNED[key] = (data, tuple(sorted(found)))
    return hit


def module_files(module, names, root=PACKAGE):
    """The package files (relative to ``root``, the package's folder, named as the package) a statement ``from
    module import names`` takes code from: the module's file, or for a package the files of the submodules it
    names and, if it names anything else, the package's ``__init__.py``.  Empty for a module outside the
    package."""
    root = Path(root)
    parts = module.split(".")
    if parts[0] != root.name:
        return []
    base = root.joinpath(*parts[1:])
    if base.with_suffix(".py").is_file():
        return [base.with_suffix(".py").relative_to(root).as_posix()]
    if not (base / "__init__.py").is_file():
        return []
    out, rest = [], False
    for n in names:
        for sub in (base / f"{n}.py", base / n / "__init__.py"):
            if sub.is_file():
                out.append(sub.relative_to(root).as_posix())
                break
        else:
            rest = True
    if rest:
        out.append((base / "__init__.py").relative_to(root).as_posix())
    return out


def imports_of(name, root=PACKAGE):
    """The package files that file ``name`` (relative to ``root``) imports at module level (sorted): read from
    its source, its ``from shipsense... import ...`` statements at the start of a line (:func:`module_files`).
    A file is read once per process while it is unchanged."""
    return _scan(root, name)[1]


def sources(name, root=PACKAGE):
    """``name`` and every package file its compiled code may take code or constants from: its module-level
    imports, theirs, and so on (sorted)."""
    seen, todo = set(), [name]
    while todo:
        f = todo.pop()
        if f not in seen:
            seen.add(f)
            todo.extend(imports_of(f, root))
    return sorted(seen)


def sources_digest(name, root=PACKAGE):
    """SHA-256 of the names and contents of :func:`sources` of ``name``."""
    h = hashlib.sha256()
    for f in sources(name, root):
        h.update(f.encode() + b"\0" + _scan(root, f)[0] + b"\0")
    return h.digest()


def kernel_files(root=PACKAGE):
    """The package files that key their compiled kernels (:func:`key_on_sources` on their last line), sorted."""
    root = Path(root)
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*.py")
                  if p.read_bytes().rstrip().rpartition(b"\n")[2].startswith(b"numba_cache.key_on_sources(globals())"))


def depends(root=PACKAGE):
    """Each kernel file (:func:`kernel_files`) and the package files it imports at module level
    (:func:`imports_of`): the graph :func:`sources` follows, derived from the sources."""
    return {name: imports_of(name, root) for name in kernel_files(root)}


def key_on_sources(namespace, root=PACKAGE):
    """Stamp the cached kernels defined in a module (its ``globals()``, and the values of its dicts: kernels
    a factory made) with :func:`sources_digest`; returns how many.  Call it at the end of the module, after
    its kernels are defined (numba reads the stamp when it first loads or saves a kernel, at its first call)."""
    name = Path(namespace["__file__"]).resolve().relative_to(Path(root).resolve()).as_posix()
    digest = sources_digest(name, root)
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
