"""Pages made from the code at build time, so that they cannot drift from it.

``scenario-reference``
    One table per pydantic model of :mod:`shipsense.config` (the :class:`~shipsense.config.Scenario` and every
    model nested in it, :class:`~shipsense.config.TrackerOptions` included): every field with its type, unit,
    range and default.  The unit comes from, in this order: the field's description (a trailing ``, m.`` or a
    unit in brackets), the physical-range validator of its type (``_within(limit, unit)``), the suffix of its
    name (``_deg``, ``_hz``, ``_s``, ``_m``), or :data:`UNITS` below.  A field with no unit from any of them and
    not listed as dimensionless fails the build: a new field must say what it measures.
``cli-reference``
    ``shipsense --help`` and every command's ``--help``, from :func:`shipsense.cli.parser.build_parser`.
"""

from __future__ import annotations

import inspect
import re
import types
import typing

import annotated_types
from docutils import nodes
from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList
from pydantic import BaseModel
from pydantic_core import PydanticUndefined
from sphinx.errors import ExtensionError

# Fields whose unit neither their description, their type's range validator nor their name states.  "-" is a
# dimensionless number, a count, a flag or a name.  Keys are (model, field); a key here that the models no
# longer have fails the build too, so this table cannot outlive the code it describes.
UNITS = {
    ("Scenario", "name"): "-", ("Scenario", "description"): "-", ("Scenario", "steps"): "samples",
    ("Scenario", "runs"): "-", ("Scenario", "seed"): "-",
    ("SensorConfig", "id"): "-", ("SensorConfig", "type"): "-", ("SensorConfig", "kind"): "-",
    ("SensorConfig", "noise_std"): "SI of the channel: T, V/m, rad",
    ("SensorConfig", "noise_var"): "SI squared: T², (V/m)², rad²",
    ("SensorConfig", "orientation"): "- (rotation matrix)",
    ("PriorConfig", "range"): "m", ("PriorConfig", "speed"): "m/s", ("PriorConfig", "moment"): "A·m² (magnitude)",
    ("PriorConfig", "p"): "A·m",
    ("NoiseConfig", "model"): "-", ("NoiseConfig", "eps"): "- (probability)",
    ("NoiseConfig", "outlier_scale"): "- (times the noise std)", ("NoiseConfig", "dropout"): "- (probability)",
    ("EnvelopeChainConfig", "mode"): "-", ("EnvelopeChainConfig", "raw_noise_std"): "V/m",
    ("SeismicConfig", "mode"): "-",
    ("SeismicConfig", "amplitude"): "arbitrary (RMS at range_ref; the bearing is scale-free)",
    ("SeismicConfig", "range_ref"): "m", ("SeismicConfig", "range_exponent"): "-",
    ("SeismicConfig", "sensor_noise"): "units of amplitude",
    ("SeismicConfig", "multipath_gain"): "- (relative amplitude)",
    ("SeismicConfig", "noise_dof"): "- (Student-t degrees of freedom)",
    ("ProcessNoiseConfig", "model"): "-", ("ProcessNoiseConfig", "sigma_q"): "SI of the state, squared",
    ("ProcessNoiseConfig", "q_diag"): "m², (m/s)², then the parameters' SI squared",
    ("ProcessNoiseConfig", "sigma_a"): "m/s²",
    ("ProcessNoiseConfig", "param_var"): "per step: (A·m²)², m², (A·m)²",
    ("BankConfig", "initial_velocity"): "m/s", ("BankConfig", "initial_course"): "-",
    ("BankConfig", "bearing_convention"): "-", ("BankConfig", "position_std"): "m",
    ("BankConfig", "velocity_std"): "m/s", ("BankConfig", "moment_std"): "A·m²", ("BankConfig", "z_std"): "m",
    ("BankConfig", "p_std"): "A·m", ("BankConfig", "prune_nats"): "nats", ("BankConfig", "ambiguity_nats"): "nats",
    ("BankConfig", "divergence_window"): "samples", ("BankConfig", "range_correction"): "-",
    ("TrackerOptions", "method"): "-", ("TrackerOptions", "unit"): "-", ("TrackerOptions", "robust"): "-",
    ("TrackerOptions", "huber_gamma"): "- (whitened residual)", ("TrackerOptions", "snr_start"): "- (SNR)",
    ("TrackerOptions", "refine"): "- (grid minima per stage)", ("TrackerOptions", "explore_samples"): "samples",
    ("TrackerOptions", "grid_samples"): "samples", ("TrackerOptions", "keep_init"): "-",
    ("TrackerOptions", "keep"): "-", ("TrackerOptions", "refit_every"): "samples",
    ("TrackerOptions", "through_peak"): "- (fraction of the peak)", ("TrackerOptions", "nis_window"): "samples",
    ("TrackerOptions", "nis_limit"): "- (NIS per component)", ("TrackerOptions", "max_restarts"): "-",
    ("TrackerOptions", "collapse"): "- (fraction)", ("TrackerOptions", "ambiguity_nats"): "nats",
    ("TrackerOptions", "report_nats"): "nats", ("TrackerOptions", "gof"): "- (test level)",
    ("TrackerOptions", "inflate"): "- (factor)", ("TrackerOptions", "history"): "samples",
    ("TrackerOptions", "consistency_window"): "samples", ("TrackerOptions", "consistency_level"): "- (test level)",
    ("TrackerOptions", "rescan"): "-", ("TrackerOptions", "early_starts"): "-",
    ("TrackerConfig", "filter"): "-", ("TrackerConfig", "n_pu"): "-",
    ("ManoeuvreConfig", "body_fixed_share"): "- (fraction)", ("SpeedChangeConfig", "factor"): "- (ratio)",
    ("RandomManoeuvreConfig", "probability"): "- (probability)",
    ("RandomManoeuvreConfig", "turn_share"): "- (fraction)",
    ("MotionConfig", "model"): "-", ("MotionConfig", "hull_share"): "- (fraction)",
    ("MotionConfig", "manoeuvre_prior"): "- (probability)", ("MotionConfig", "threshold"): "- (probability)",
    ("TrafficConfig", "count"): "ships", ("TrafficConfig", "geometry"): "-",
    ("TrafficConfig", "speed_ratio"): "- (ratio)",
}

SUFFIXES = {"_deg": "degrees", "_hz": "Hz", "_s": "s", "_m": "m"}
TOML_TABLE = {"Scenario": "top level", "SensorConfig": "[[sensors]]", "MediumConfig": "[medium]",
              "EarthConfig": "[earth]", "PassageConfig": "[passage]", "PriorConfig": "[prior]",
              "NoiseConfig": "[noise]", "EnvelopeChainConfig": "[envelope_chain]", "SeismicConfig": "[seismic]",
              "TrackerOptions": "[tracker] (the project's tracker)",
              "TrackerConfig": "[tracker] (the source studies' filter and bank)",
              "ProcessNoiseConfig": "[tracker.process_noise]", "BankConfig": "[tracker.bank]",
              "ManoeuvreConfig": "[manoeuvres]", "TurnConfig": "[[manoeuvres.turns]]",
              "SpeedChangeConfig": "[[manoeuvres.speed_changes]]", "RandomManoeuvreConfig": "[manoeuvres.random]",
              "MotionConfig": "[tracker.motion]", "TrafficConfig": "[traffic]"}


def _strip_annotated(tp):
    """(bare type, metadata list) of a possibly nested ``Annotated``."""
    meta = []
    while typing.get_origin(tp) is typing.Annotated:
        args = typing.get_args(tp)
        tp, meta = args[0], meta + list(args[1:])
    return tp, meta


def _type_name(tp) -> str:
    tp, _ = _strip_annotated(tp)
    origin = typing.get_origin(tp)
    if tp is type(None):
        return "none"
    if origin is typing.Literal:
        return " | ".join(f'"{a}"' if isinstance(a, str) else repr(a) for a in typing.get_args(tp))
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp) if a is not type(None))
    if origin in (tuple,):
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of {_type_name(args[0])}"
        if args and all(_strip_annotated(a)[0] is _strip_annotated(args[0])[0] for a in args):
            inner = _type_name(args[0])
            return f"[{inner}] x {len(args)}" if not inner.startswith("[") else f"{len(args)} x ({inner})"
        return "[" + ", ".join(_type_name(a) for a in args) + "]"
    if origin is list:
        (arg,) = typing.get_args(tp)
        return f"array of {_type_name(arg)}"
    if inspect.isclass(tp) and issubclass(tp, BaseModel):
        return f"table ({tp.__name__})"
    return {float: "number", int: "integer", str: "string", bool: "true | false"}.get(tp, getattr(tp, "__name__",
                                                                                                  str(tp)))


def _walk_metadata(tp):
    """Every metadata object of a type and of the types inside it (unions, tuples, lists)."""
    tp, meta = _strip_annotated(tp)
    yield from meta
    for arg in typing.get_args(tp) if typing.get_origin(tp) is not typing.Literal else ():
        if arg is not Ellipsis:
            yield from _walk_metadata(arg)


def _validator_facts(tp):
    """(constraints, unit) read from a type's metadata: pydantic/annotated-types bounds, and this package's
    ``_finite`` / ``_positive`` / ``_within(limit, unit)`` validators (their closures hold limit and unit)."""
    facts, unit = [], None
    for m in _walk_metadata(tp):
        for name, sym in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"), ("min_length", "length >="),
                          ("max_length", "length <=")):
            value = getattr(m, name, None)
            if isinstance(m, (annotated_types.BaseMetadata, annotated_types.GroupedMetadata)) or hasattr(m, name):
                if value is not None and not callable(value):
                    facts.append(f"{sym} {value:g}" if isinstance(value, float) else f"{sym} {value}")
        if type(m).__name__ == "FieldInfo":
            for sub in m.metadata:
                facts += _validator_facts(typing.Annotated[object, sub])[0]
        func = getattr(m, "func", None)
        if func is None:
            continue
        fname = getattr(func, "__name__", "")
        if fname == "_positive":
            facts.append("> 0")
        elif fname == "_range":
            facts.append("[min, max], min <= max")
        elif fname == "check" and func.__closure__:
            cells = dict(zip(func.__code__.co_freevars, (c.cell_contents for c in func.__closure__)))
            if "limit" in cells:
                facts.append(f"|value| <= {cells['limit']:g}")
                unit = unit or (cells.get("unit") or None)
    seen = []
    for f in facts:
        if f not in seen:
            seen.append(f)
    return seen, unit


_UNIT_WORDS = re.compile(r"[A-Za-z·²/() ]{1,12}")


def _unit(model: str, name: str, field, type_unit) -> str | None:
    desc = field.description or ""
    tail = desc.rstrip().removesuffix(".").rpartition(",")[2].strip()   # "Source (x, y) at t = 0, m."
    if "," in desc and _UNIT_WORDS.fullmatch(tail) and len(tail.split()) == 1:
        return tail
    m = re.search(r"\((A·m²|A·m|m|s|m/s|S/m|V/m|T)\)", desc)
    if m:
        return m.group(1)
    if type_unit and type_unit not in ("(SI)", "(SI²)"):
        return type_unit
    for suffix, unit in SUFFIXES.items():
        if name.endswith(suffix):
            return unit
    return UNITS.get((model, name))


def _plain(text: str) -> str:
    """A field's description (plain text) escaped for reStructuredText: ``|p|`` is no substitution."""
    for ch in "\\|*`_":
        text = text.replace(ch, "\\" + ch)
    return text


def _default(field) -> str:
    if field.is_required():
        return "**required**"
    value = field.default
    if value is PydanticUndefined:
        return "—"
    if isinstance(value, BaseModel):
        return "(its defaults)"
    if value is None:
        return "none"
    if isinstance(value, str):
        return f'``"{value}"``' if value else '``""``'
    if isinstance(value, bool):
        return f"``{str(value).lower()}``"
    if isinstance(value, tuple):
        value = list(value)
    if isinstance(value, float):
        return f"``{value:g}``"
    return f"``{value!r}``"


def _nested(tp):
    tp, _ = _strip_annotated(tp)
    if inspect.isclass(tp) and issubclass(tp, BaseModel):
        yield tp
    for arg in typing.get_args(tp):
        if arg is not Ellipsis and typing.get_origin(tp) is not typing.Literal:
            yield from _nested(arg)


def scenario_models():
    """The models a scenario file is made of, in the order a reader meets them (depth first)."""
    from shipsense.config import Scenario, TrackerOptions

    order = []

    def visit(cls):
        if cls in order:
            return
        order.append(cls)
        for f in cls.model_fields.values():
            for sub in _nested(f.annotation):
                visit(sub)
    visit(Scenario)
    if TrackerOptions not in order:
        order.append(TrackerOptions)
    return order


def _first_paragraph(doc: str) -> str:
    doc = inspect.cleandoc(doc or "")
    return doc


def scenario_rst() -> list[str]:
    from shipsense.config import TrackerConfig, TrackerOptions

    seen_keys, missing, lines = set(), [], []
    for cls in scenario_models():
        own = cls.model_fields
        if cls is TrackerConfig:   # the [tracker] table: its own keys here, the tracker's options below
            own = {k: v for k, v in own.items() if k not in TrackerOptions.model_fields}
        title = f"``{TOML_TABLE.get(cls.__name__, cls.__name__)}``: :class:`~shipsense.config.{cls.__name__}`"
        lines += [title, "-" * len(title), ""]
        lines += _first_paragraph(cls.__doc__).splitlines() + [""]
        if cls is TrackerConfig:
            lines += ["The ``[tracker]`` table also takes every key of the project's tracker, "
                      "``[tracker] (the project's tracker)`` below.", ""]
        lines += [".. list-table::", "   :header-rows: 1", "   :widths: 14 20 12 20 12 32", "",
                  "   * - key", "     - type", "     - unit", "     - range", "     - default", "     - meaning"]
        for name, field in own.items():
            constraints, type_unit = _validator_facts(field.annotation)
            if field.metadata:   # pydantic moves a top-level Annotated's constraints and validators here
                more, more_unit = _validator_facts(typing.Annotated[object, *field.metadata])
                constraints += [c for c in more if c not in constraints]
                type_unit = type_unit or more_unit
            unit = _unit(cls.__name__, name, field, type_unit)
            nested = list(_nested(field.annotation))
            if unit is None and nested:
                unit = "-"
            if unit is None:
                missing.append(f"{cls.__name__}.{name}")
            seen_keys.add((cls.__name__, name))
            desc = _plain(field.description or "").replace("\n", " ")   # plain text, not reStructuredText
            if nested and not desc:
                desc = "a table: " + ", ".join(f"``{TOML_TABLE.get(n.__name__, n.__name__)}``" for n in nested)
            rng = ", ".join(f"``{c}``" for c in constraints) or "—"
            unit = unit or "?"
            unit = "—" + unit[1:] if unit.startswith("-") else unit   # dimensionless (a lone "-" is a bullet)
            lines += [f"   * - ``{name}``", f"     - ``{_type_name(field.annotation)}``", f"     - {unit}",
                      f"     - {rng}", f"     - {_default(field)}", f"     - {desc or '—'}"]
        lines.append("")
    stale = sorted(set(UNITS) - seen_keys)
    if missing or stale:
        raise ExtensionError("scenario reference: " + (
            f"no unit for {', '.join(missing)} (give the field a description ending in its unit, or add it to "
            "UNITS in docs/_ext/shipsense_docs.py)" if missing else "") + (
            f"; UNITS names fields the models no longer have: {stale}" if stale else ""))
    return lines


def cli_rst() -> list[str]:
    from shipsense.cli.parser import build_parser

    parser = build_parser()
    lines = ["``shipsense``", "-------------", "", ".. code-block:: text", ""]
    lines += ["   " + ln for ln in parser.format_help().splitlines()] + [""]
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, p in sub.choices.items():
        title = f"``shipsense {name}``"
        lines += [title, "-" * len(title), "", ".. code-block:: text", ""]
        lines += ["   " + ln for ln in p.format_help().splitlines()] + [""]
    return lines


class _Generated(Directive):
    has_content = False
    make = None

    def run(self):
        container = nodes.section()
        container.document = self.state.document
        source = self.state.document.current_source
        self.state.nested_parse(StringList(type(self).make(), source=source), self.content_offset, container,
                                match_titles=True)
        return container.children


class ScenarioReference(_Generated):
    make = staticmethod(scenario_rst)


class CliReference(_Generated):
    make = staticmethod(cli_rst)


def _import_target(target: str, modname: str | None, clsname: str | None):
    """The object a dotted ``target`` names, tried as given and relative to the referring module and class
    (as Sphinx searches), or None.  Returns (object, the full name it was found under)."""
    import importlib

    candidates = [target]
    if modname:
        if clsname:
            candidates.append(f"{modname}.{clsname}.{target}")
        candidates.append(f"{modname}.{target}")
    for full in candidates:
        parts = full.split(".")
        for i in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:i]))
            except ImportError:
                continue
            try:
                for attr in parts[i:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return obj, full
    return None, None


def _documented(domain, name):
    return name in domain.objects


ROLE_TYPES = {"func": {"function"}, "meth": {"method", "classmethod", "staticmethod", "property"},
              "class": {"class", "exception"}, "exc": {"exception", "class"}, "mod": {"module"},
              "attr": {"attribute", "property", "data"}, "data": {"data", "attribute"},
              "obj": None, "const": {"data", "attribute"}}


def _by_suffix(domain, target, role, modname):
    """The one documented shipsense object of the role's kind whose full name ends with ``.target`` (as
    Sphinx's own search for ``.name`` does), preferring the referring module's own; None when there is none or
    more than one."""
    kinds = ROLE_TYPES.get(role)
    hits = [n for n, o in domain.objects.items() if n.startswith("shipsense") and n.endswith("." + target)
            and (kinds is None or o.objtype in kinds)]
    local = [n for n in hits if modname and n.startswith(modname + ".")]
    for group in (local, hits):
        if len(group) == 1:
            return group[0]
    return None


def _declared_field(owner, attr):
    """Whether class ``owner`` declares ``attr`` as a field (dataclass, NamedTuple or annotated attribute)."""
    return inspect.isclass(owner) and any(attr in getattr(c, "__annotations__", {}) for c in owner.__mro__)


def resolve_alias(app, env, node, contnode):
    """Resolve a ``py:`` reference to a shipsense name that exists but is documented under another name.

    * The API reference documents each object once, where it is defined
      (``shipsense.trackers.tracker.tracker.Tracker``); docstrings also name it where it is re-exported
      (``shipsense.trackers.Tracker``, ``shipsense.load_scenario``): resolved to the defining name.
    * A short name (``Tracker.update``) is resolved when exactly one documented shipsense object has it as its
      last components (an autosummary table shows a module's first line on its parent's page, away from the
      module the name is relative to).
    * A module attribute without a docstring of its own links to its module's page; a private name
      (``_Model``, ``FieldModel._h_and_H_numpy``) that exists is shown as text, since private names are not
      documented.
    * Anything else stays unresolved, and ``-W`` fails the build.
    """
    if node.get("refdomain") != "py":
        return None
    domain = env.get_domain("py")
    builder = app.builder
    target = node["reftarget"].lstrip(".~")

    def ref(name):
        return domain.resolve_xref(env, node["refdoc"], builder, domain.objects[name].objtype, name, node, contnode)

    obj, full = _import_target(target, node.get("py:module"), node.get("py:class"))
    if obj is not None and (full or "").startswith("shipsense"):
        name = obj.__name__ if inspect.ismodule(obj) else (
            f"{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', '')}"
            if getattr(obj, "__qualname__", None) else None)
        if name and _documented(domain, name):
            return ref(name)
    role, modname = node.get("reftype"), node.get("py:module")
    hit = _by_suffix(domain, target, role, modname)
    if hit:
        return ref(hit)
    if obj is None and "." in target:     # Class.attribute where the class is known by its short name
        owner_name, _, attr = target.rpartition(".")
        owner = _by_suffix(domain, owner_name, "class", modname)
        if owner:
            cls, _ = _import_target(owner, None, None)
            if _declared_field(cls, attr):          # a dataclass field: the class documents it
                return ref(owner)
            obj, full = _import_target(f"{owner}.{attr}", None, None)
    elif obj is None and modname:         # a private method named from a module's summary table
        for name, o in domain.objects.items():
            if o.objtype == "class" and name.startswith(modname + "."):
                cls, _ = _import_target(name, None, None)
                if target.startswith("_") and hasattr(cls, target):
                    return contnode
    if obj is None or not (full or "").startswith("shipsense"):
        return None
    if any(p.startswith("_") and not p.startswith("__") for p in full.split(".")):
        return contnode                              # a private name: text, not a link
    owner = full.rpartition(".")[0]
    while owner and not _documented(domain, owner):  # a documented module or class that holds it
        owner = owner.rpartition(".")[0]
    return ref(owner) if owner else None


def _public_modules(package="shipsense"):
    """Every public module of the package (no component starting with ``_``), in import order of names."""
    import importlib
    import pkgutil

    root = importlib.import_module(package)
    names = [package]
    for info in pkgutil.walk_packages(root.__path__, prefix=package + "."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def _members(modname):
    """(functions, classes, exceptions) defined in the module itself, public, in source order."""
    import importlib

    mod = importlib.import_module(modname)
    out = {"function": [], "class": [], "exception": []}
    for name, obj in vars(mod).items():
        if name.startswith("_") or getattr(obj, "__module__", None) != modname:
            continue
        if inspect.isclass(obj):
            out["exception" if issubclass(obj, BaseException) else "class"].append(name)
        elif inspect.isfunction(obj) or type(obj).__name__ == "CPUDispatcher":
            out["function"].append(name)
    return out


def _summary(modname, name):
    """The first paragraph of a docstring, on one line (whole, so that its literals and roles stay closed)."""
    import importlib

    doc = inspect.getdoc(getattr(importlib.import_module(modname), name)) or ""
    first = doc.split("\n\n")[0].strip()
    if first.startswith((">>>", "..")):
        return "—"
    return " ".join(first.split()) or "—"


def _documented_attributes(modname):
    """Module-level names with a ``#:`` comment or a docstring after them (what autodoc can document)."""
    from sphinx.pycode import ModuleAnalyzer

    try:
        analyzer = ModuleAnalyzer.for_module(modname)
        analyzer.analyze()
    except Exception:   # a module without source: nothing to add
        return []
    return [name for (cls, name) in analyzer.attr_docs if cls == "" and not name.startswith("_")]


def generate_api(app):
    """Write ``docs/api/generated/<module>.rst`` for every public module of the package (at every build; the
    folder is build output, not committed).  Each page: the module's docstring, tables of its functions and
    classes, then each documented where it is defined (re-exports are not repeated); a package's page lists its
    modules.  Walking the package, not a list, means a module added or split appears by itself."""
    from pathlib import Path

    out = Path(app.srcdir) / "api" / "generated"
    out.mkdir(parents=True, exist_ok=True)
    modules = _public_modules()
    keep = set()
    for modname in modules:
        title = modname.replace("_", r"\_")
        lines = [title, "=" * len(title), "", f".. automodule:: {modname}", "   :no-members:", ""]
        children = [m for m in modules if m.rpartition(".")[0] == modname]
        if children:
            lines += [".. rubric:: Modules", "", ".. toctree::", "   :maxdepth: 1", ""]
            lines += [f"   {m}" for m in children] + [""]
        members = _members(modname)
        for kind, heading in (("function", "Functions"), ("class", "Classes"), ("exception", "Exceptions")):
            if members[kind]:
                lines += [f".. rubric:: {heading}", "", f".. currentmodule:: {modname}", "",
                          ".. list-table::", "   :widths: 25 75", ""]
                role = "func" if kind == "function" else "class" if kind == "class" else "exc"
                for n in members[kind]:
                    lines += [f"   * - :{role}:`{n}`", f"     - {_summary(modname, n)}"]
                lines.append("")
        if any(members.values()):
            lines += [".. rubric:: Reference", ""]
            for name in members["function"]:
                lines += [f".. autofunction:: {name}", ""]
            for name in members["class"] + members["exception"]:
                lines += [f".. autoclass:: {name}", "   :members:", "   :show-inheritance:",
                          "   :member-order: bysource", ""]
            attrs = _documented_attributes(modname)
            if attrs:
                lines += [".. rubric:: Module attributes", ""]
                lines += [ln for a in attrs for ln in (f".. autodata:: {a}", "   :no-value:", "")]
        text = "\n".join(lines)
        path = out / f"{modname}.rst"
        keep.add(path.name)
        if not path.exists() or path.read_text() != text:   # unchanged pages are not re-read
            path.write_text(text)
    for stale in out.glob("*.rst"):
        if stale.name not in keep:
            stale.unlink()


def setup(app):
    app.connect("builder-inited", generate_api)
    app.connect("missing-reference", resolve_alias)
    directives.register_directive("scenario-reference", ScenarioReference)
    directives.register_directive("cli-reference", CliReference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
