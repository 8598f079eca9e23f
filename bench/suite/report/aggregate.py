"""The report's figures from the results: rows grouped by study and averaged over scores.

Both the charts (:mod:`bench.suite.report.charts`) and the Markdown sections
(:mod:`bench.suite.report.sections`) read the results through these groupings and means, so a chart
and the table beside it always show the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from bench.suite.results import Row, RowFigure, ScoreMetric, SuiteResults, is_k_row

__all__ = [
    "FieldKey",
    "aggregate",
    "chain_rows",
    "density_rows",
    "environment_names",
    "field_label",
    "finite_mean",
    "k_rows",
    "ldr_pairs",
    "mean_figure",
    "pareto_front",
    "pareto_points",
]

#: A field of the density sweep: (S cameras, T lights, points).
FieldKey = tuple[int, int, int]


def finite_mean(values: Iterable[float | None]) -> float:
    """The mean of the finite values.

    Parameters
    ----------
    values : floats, None and non-finite ones ignored

    Returns
    -------
    float, NaN when none is finite
    """
    kept = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(kept)) if kept else float("nan")


def aggregate(
    rows: Sequence[Row],
    metric: ScoreMetric,
    *,
    view: str | None = None,
    ldr: bool | None = False,
    environment: str | None = None,
) -> float:
    """Mean of a score over rows (scenes) and their scores (environments, views).

    Parameters
    ----------
    rows : the rows to average
    metric : the score
    view : str, optional, only this view (None takes both)
    ldr : bool, optional, only LDR or only HDR environments (None takes both)
    environment : str, optional, only this environment

    Returns
    -------
    float, :func:`finite_mean` of the chosen scores
    """
    return finite_mean(
        s[metric]
        for r in rows
        for s in r["scores"]
        if (view is None or s["view"] == view)
        and (ldr is None or s["ldr"] == ldr)
        and (environment is None or s["environment"] == environment)
    )


def mean_figure(rows: Sequence[Row], key: RowFigure) -> float:
    """The mean of a per-row figure (a time or the memory) over rows.

    Parameters
    ----------
    rows : Row; key : the figure

    Returns
    -------
    float, :func:`finite_mean` of the rows' figures
    """
    return finite_mean(r[key] for r in rows)


def chain_rows(results: SuiteResults) -> dict[str, list[Row]]:
    """The ablation rows on the chain field, by method label in chain order.

    Parameters
    ----------
    results : SuiteResults

    Returns
    -------
    dict of label to rows (one per scene); labels without rows left out
    """
    out: dict[str, list[Row]] = {label: [] for label in results["chain"]}
    for r in results["rows"]:
        if r["study"] == "ablation":
            out[r["label"]].append(r)
    return {label: rows for label, rows in out.items() if rows}


def k_rows(results: SuiteResults) -> dict[str, dict[int, list[Row]]]:
    """The K sweep's rows by family and K, K ascending.

    Parameters
    ----------
    results : SuiteResults

    Returns
    -------
    dict of family to (dict of K to rows)

    Raises
    ------
    ValueError
        For a K-sweep row without a K (a sweep over sampled lights always has one).
    """
    out: dict[str, dict[int, list[Row]]] = {}
    for r in results["rows"]:
        if is_k_row(r):
            k = r["k"]
            if k is None:
                raise ValueError(f"the K-sweep row {r['label']!r} has no K")
            out.setdefault(r["family"], {}).setdefault(k, []).append(r)
    return {family: dict(sorted(by_k.items())) for family, by_k in out.items()}


def density_rows(results: SuiteResults) -> dict[str, dict[FieldKey, list[Row]]]:
    """Rows of the density methods by label and field (S, T, points); the chain field too.

    Parameters
    ----------
    results : SuiteResults

    Returns
    -------
    dict of label to (dict of field to rows), fields by T then S; labels without rows left out
    """
    out: dict[str, dict[FieldKey, list[Row]]] = {label: {} for label in results["density_methods"]}
    for r in results["rows"]:
        if r["label"] in out and r["study"] in ("ablation", "density"):
            out[r["label"]].setdefault((r["S"], r["T"], r["points"]), []).append(r)
    return {
        label: dict(sorted(by_field.items(), key=lambda item: (item[0][1], item[0][0])))
        for label, by_field in out.items()
        if by_field
    }


def pareto_points(results: SuiteResults) -> dict[str, tuple[float, float]]:
    """Mean time per new lighting and mean HDR error of every method on the chain field.

    Parameters
    ----------
    results : SuiteResults

    Returns
    -------
    dict of label to (ms per new lighting, relative RMSE), over the ablation and K rows
    """
    by_label: dict[str, list[Row]] = {}
    cameras, lights = results["chain_field"][:2]
    for r in results["rows"]:
        if r["study"] in ("ablation", "k") and (r["S"], r["T"]) == (cameras, lights):
            by_label.setdefault(r["label"], []).append(r)
    return {
        label: (mean_figure(rows, "new_lighting_ms"), aggregate(rows, "relative_rmse"))
        for label, rows in by_label.items()
    }


def pareto_front(points: dict[str, tuple[float, float]]) -> list[str]:
    """The labels no other point beats in both time and error, fastest first.

    Parameters
    ----------
    points : dict of label to (time, error)

    Returns
    -------
    list of str
    """
    ordered = sorted(points, key=lambda label: (points[label][0], points[label][1]))
    front: list[str] = []
    best = math.inf
    for label in ordered:
        error = points[label][1]
        if error < best:
            front.append(label)
            best = error
    return front


def ldr_pairs(results: SuiteResults) -> list[tuple[str, str]]:
    """(HDR, LDR) environment name pairs present in the results.

    Parameters
    ----------
    results : SuiteResults

    Returns
    -------
    list of (HDR name, LDR name), for each LDR photo whose HDR panorama was measured too
    """
    envs = results["environments"]
    return [
        (env["truth"], name) for name, env in envs.items() if env["ldr"] and env["truth"] in envs
    ]


def environment_names(results: SuiteResults, *, ldr: bool | None = None) -> list[str]:
    """The environments' names in the results' order.

    Parameters
    ----------
    results : SuiteResults
    ldr : bool, optional, only LDR or only HDR ones (None takes all)

    Returns
    -------
    list of str
    """
    return [
        name for name, env in results["environments"].items() if ldr is None or env["ldr"] == ldr
    ]


def field_label(field: FieldKey) -> str:
    """A field's name in tables and on the density chart: ``S=10 T=10 (20k pts)``.

    Parameters
    ----------
    field : FieldKey

    Returns
    -------
    str
    """
    cameras, lights, points = field
    return f"S={cameras} T={lights} ({points // 1000}k pts)"
