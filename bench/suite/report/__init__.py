"""REPORT.md and the charts of the speed-against-accuracy suite, from its results alone.

:func:`write_report` reads nothing but the results (``results.json`` of :mod:`bench.suite`,
laid out as :class:`bench.suite.results.SuiteResults`), so a report can be regenerated, or
extended with other modules' sections (``extra_sections``), without running anything again.
The figures come from :mod:`bench.suite.report.aggregate`, the charts from
:mod:`bench.suite.report.charts` and the text from :mod:`bench.suite.report.sections`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from bench.advisor import advisor_chart
from bench.held_out import held_out_chart
from bench.suite.report.aggregate import pareto_front
from bench.suite.report.charts import CHARTS, draw_charts
from bench.suite.report.sections import report_sections
from bench.suite.results import SuiteResults

# CHARTS and pareto_front are where the tests have always imported them from.
__all__ = ["CHARTS", "pareto_front", "write_report"]


def write_report(
    results: SuiteResults, directory: Path, extra_sections: Sequence[str] | None = None
) -> Path:
    """Draw the charts and write ``directory/REPORT.md`` from the suite's results.

    Parameters
    ----------
    results : SuiteResults, as :func:`bench.suite.run_suite` returns it (or results.json read
        back)
    directory : Path, where the charts and REPORT.md go
    extra_sections : sequence of str, optional
        Markdown sections of other studies (each starting with its own ``## `` heading),
        appended after the suite's own, in order.

    Returns
    -------
    Path of REPORT.md
    """
    directory.mkdir(parents=True, exist_ok=True)
    front = draw_charts(results, directory)
    if results.get("advisor"):
        advisor_chart(results["advisor"], directory / "advisor.png")
    if results.get("held_out"):
        held_out_chart(results["held_out"], directory / "held_out.png")
    lines = [
        "# Relighting: speed against accuracy",
        "",
        "Generated from results.json by `bench.suite.report.write_report`; every figure below was "
        "measured in the same run.",
        "",
        *report_sections(results, front),
    ]
    for section in extra_sections or ():
        lines += [section.rstrip("\n"), ""]
    path = directory / "REPORT.md"
    path.write_text("\n".join(lines).rstrip("\n") + "\n")
    return path
