"""The report's charts, drawn from the results alone: Pareto, K, field density, LDR against HDR.

Each chart is a PNG beside REPORT.md (:data:`CHARTS`); the figures on it come from
:mod:`bench.suite.report.aggregate`, as the tables' do.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from bench.suite.report.aggregate import (
    aggregate,
    chain_rows,
    density_rows,
    field_label,
    k_rows,
    ldr_pairs,
    pareto_front,
    pareto_points,
)
from bench.suite.results import SuiteResults

__all__ = ["CHARTS", "draw_charts"]

#: The charts :func:`draw_charts` draws, file name to caption.
CHARTS = {
    "pareto.png": "error against time per new lighting",
    "error_vs_k.png": "error against K",
    "error_vs_density.png": "error against field density",
    "ldr_vs_hdr.png": "LDR against HDR panoramas",
}


def _chart_pareto(results: SuiteResults, path: Path) -> list[str]:
    points = pareto_points(results)
    front = pareto_front(points)
    figure, axis = plt.subplots(figsize=(8, 5))
    chain = {
        r["label"] for r in results["rows"] if r["study"] == "ablation" and r["role"] == "chain"
    }
    below = False
    for label, (ms, error) in points.items():
        # Steps of the chain in colour and named; the K sweep and the branches as grey dots,
        # named only where they make the front (the rest would bury the chart in labels).
        if label in chain:
            axis.scatter([ms], [100 * error], s=36, marker="o", zorder=3)
        else:
            axis.scatter([ms], [100 * error], s=12, marker=".", color="0.55", zorder=2)
        if label in chain or label in front:
            below = not below  # alternate sides: neighbouring steps often sit close
            axis.annotate(
                label, (ms, 100 * error), fontsize=7, xytext=(4, -9 if below else 3),
                textcoords="offset points",
            )  # fmt: skip
    xs = [points[label][0] for label in front]
    ys = [100 * points[label][1] for label in front]
    axis.step(xs, ys, where="post", color="black", linewidth=1, label="Pareto front")
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.set_xlabel("time per new lighting (set_lighting + render), ms, log scale")
    axis.set_ylabel("relative RMSE, % (log; mean of scenes, HDR panoramas, views)")
    cameras, lights, points_count, size = results["chain_field"]
    axis.set_title(
        f"Error against time, S={cameras} T={lights}, {points_count} points, {size} px views"
    )
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return front


def _chart_k(results: SuiteResults, path: Path) -> None:
    figure, axis = plt.subplots(figsize=(7, 4.5))
    for family, by_k in k_rows(results).items():
        for view, style in (("between", "-"), ("captured", "--")):
            axis.plot(
                list(by_k),
                [100 * aggregate(rows, "relative_rmse", view=view) for rows in by_k.values()],
                style,
                marker="o",
                label=f"{family}, {view} view",
            )
    axis.set_xscale("log", base=2)
    axis.set_xlabel("K, sampled lights")
    axis.set_ylabel("relative RMSE, % (mean of scenes, HDR panoramas)")
    axis.set_title("Error against K")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _chart_density(results: SuiteResults, path: Path) -> None:
    figure, axis = plt.subplots(figsize=(7, 4.5))
    density = density_rows(results)
    fields = sorted(
        {f for by_field in density.values() for f in by_field}, key=lambda f: (f[1], f[0])
    )
    positions = {f: i for i, f in enumerate(fields)}
    for label, by_field in density.items():
        axis.plot(
            [positions[f] for f in by_field],
            [100 * aggregate(rows, "relative_rmse", view="between") for rows in by_field.values()],
            marker="o",
            label=label,
        )
    axis.set_xticks(range(len(fields)), [field_label(f) for f in fields], fontsize=7)
    axis.set_yscale("log")
    axis.set_xlabel("field (S cameras, T lights)")
    axis.set_ylabel("relative RMSE, %, between view (log)")
    axis.set_title("Error against field density")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _chart_ldr(results: SuiteResults, path: Path) -> None:
    pairs = ldr_pairs(results)
    chain = chain_rows(results)
    figure, axis = plt.subplots(figsize=(8, 4.5))
    width = 0.8 / max(2 * len(pairs), 1)
    labels = list(chain)
    for i, (hdr, ldr) in enumerate(pairs):
        for j, (name, hatch) in enumerate(((hdr, ""), (ldr, "//"))):
            offset = (2 * i + j) * width - 0.4 + width / 2
            axis.bar(
                [x + offset for x in range(len(labels))],
                [
                    100 * aggregate(chain[label], "relative_rmse", ldr=None, environment=name)
                    for label in labels
                ],
                width,
                hatch=hatch,
                label=name,
                color=f"C{i}",
                alpha=0.55 if hatch else 0.9,
            )
    axis.set_xticks(range(len(labels)), labels, rotation=30, ha="right", fontsize=7)
    axis.set_yscale("log")
    axis.set_ylabel("relative RMSE against the HDR truth, % (log)")
    axis.set_title("LDR photo against HDR panorama as the lighting (mean of scenes, both views)")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def draw_charts(results: SuiteResults, directory: Path) -> list[str]:
    """Draw every chart of :data:`CHARTS` into ``directory``.

    Parameters
    ----------
    results : SuiteResults
    directory : Path, an existing directory

    Returns
    -------
    list of str, the Pareto front's labels, fastest first (the report names them)
    """
    front = _chart_pareto(results, directory / "pareto.png")
    _chart_k(results, directory / "error_vs_k.png")
    _chart_density(results, directory / "error_vs_density.png")
    _chart_ldr(results, directory / "ldr_vs_hdr.png")
    return front
