"""The CI gate: the observability and ambiguity verdicts of several layout files, as exit codes and JUnit XML.

``shipsense check LAYOUT.toml [...] [--junit FILE]`` checks each file
(:func:`~shipsense.design.observability.check_scenario`) and reports its two-ship resolvable separation
(:func:`~shipsense.design.resolvability.resolvable_separation`, on the same prior passages: a figure, not a
verdict -- it does not change the exit code); the exit code is
the worst outcome -- 2 a file that cannot be read or validated, 4 a
degenerate array, 3 an ambiguous one, 0 all observable -- and the JUnit
report has one test case per file (a failure for an ambiguous or degenerate
array, an error for a bad file), which CI systems display per layout; a case's ``resolvable_separation_m``
property (m; ``inf`` when the pairs are not told apart within the separations tried) and its standard output
carry the resolvability.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from xml.etree import ElementTree as ET

SEVERITY = {"observable": 0, "ambiguous": 1, "degenerate": 2, "error": 3}


@dataclass
class GateResult:
    """One layout file's outcome: its verdict (or ``"error"`` with the message), and the seconds it took."""

    layout: str
    verdict: str
    seconds: float
    detail: object = None   # the Verdict, or the error message
    scenario: object = None   # the validated Scenario (None for an error)
    resolvability: object = None   # the Resolvability (None for an error)

    @property
    def failed(self) -> bool:
        return self.verdict in ("ambiguous", "degenerate")


def check_layouts(layouts, passages=8, seed=0, progress=False, errors=(ValueError, OSError)):
    """Check each layout file; a file that cannot be loaded or validated is an ``"error"`` result (its
    message kept), not an exception, so one bad file does not hide the others' verdicts."""
    from shipsense.design.observability import check_array, scenario_passages
    from shipsense.design.resolvability import resolvable_separation

    out = []
    for layout in layouts:
        t0 = time.perf_counter()
        try:
            sc, model, thetas, motion = scenario_passages(layout, passages, seed)   # (one set-up for both checks)
            v = check_array(model, thetas, sc.steps, seed=seed, progress=progress, motion=motion)
            res = resolvable_separation(model, thetas, sc.steps)
            out.append(GateResult(str(layout), v.verdict, time.perf_counter() - t0, v, sc, res))
        except errors as err:
            out.append(GateResult(str(layout), "error", time.perf_counter() - t0, str(err)))
    return out


def worst(results) -> str:
    """The worst outcome among ``results`` (``error`` > ``degenerate`` > ``ambiguous`` > ``observable``)."""
    return max((r.verdict for r in results), key=SEVERITY.__getitem__)


def junit_xml(results) -> bytes:
    """A JUnit XML report: one test suite, one test case per layout file."""
    suite = ET.Element("testsuite", name="shipsense check", tests=str(len(results)),
                       failures=str(sum(r.failed for r in results)),
                       errors=str(sum(r.verdict == "error" for r in results)),
                       time=f"{sum(r.seconds for r in results):.3f}")
    for r in results:
        case = ET.SubElement(suite, "testcase", classname="shipsense.check", name=r.layout, time=f"{r.seconds:.3f}")
        if r.resolvability is not None:
            props = ET.SubElement(case, "properties")
            ET.SubElement(props, "property", name="resolvable_separation_m",
                          value=f"{r.resolvability.separation_m:.6g}")
        if r.verdict == "error":
            ET.SubElement(case, "error", message=str(r.detail), type="bad input")
        elif r.failed:
            v = r.detail
            text = f"{r.verdict}: closest far-apart passage at chi-square {v.min_chi2:.3g} (ambiguous below 25); " \
                   f"Fisher rank {v.fim_rank} of {len(v.labels)}"
            ET.SubElement(case, "failure", message=text, type=r.verdict).text = text
        if r.resolvability is not None:
            ET.SubElement(case, "system-out").text = r.resolvability.describe()
    ET.indent(suite)
    return ET.tostring(suite, encoding="utf-8", xml_declaration=True) + b"\n"
