"""The environment-truth study's methods, scores and report (:mod:`bench.env_truth` measures).

What is compared (the light-stage sums and the command line's variants, :data:`CLI_METHODS`),
one method's :class:`Score` on one (scene, dome, panorama), and the report drawn from the
records alone: the Markdown tables (:func:`format_tables`) and the chart (:func:`chart`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Literal, TypedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

__all__ = [
    "CLI_METHODS",
    "SLOW_CLI_METHODS",
    "SUM_FULL",
    "SUM_UPPER",
    "Records",
    "Score",
    "chart",
    "format_tables",
]

SUM_FULL = "light-stage sum (full sphere)"
SUM_UPPER = "light-stage sum (upper hemisphere)"
#: The command line's variants: (label, flags after ``rig relight FIT.lp --env P -o OUT.exr``).
#: ``--fast`` is the default choice among the quick rungs: the default proper also trains a
#: network per run (about 6 minutes at 64 x 64 on the shared machine), see SLOW_CLI_METHODS.
CLI_METHODS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("rig relight --fast", ("--fast",)),
    ("--scheme projection", ("--scheme", "projection")),
    (
        "--scheme projection --below-horizon open",
        ("--scheme", "projection", "--below-horizon", "open"),
    ),
    ("--scheme pixels --interp barycentric", ("--scheme", "pixels", "--interp", "barycentric")),
    ("--scheme model", ("--scheme", "model")),
    ("--paper", ("--paper",)),
    # The RTI tools' interpolation and fits, every grid light of the panorama predicted (what
    # a user of those tools would do); linear fits, as the capture is 16-bit linear.
    ("--method rbf", ("--method", "rbf")),
    ("--method ptm", ("--method", "ptm")),
    ("--method hsh3", ("--method", "hsh3")),
)
#: The default with nothing given (its choice includes training a network): with ``--slow``.
SLOW_CLI_METHODS: tuple[tuple[str, tuple[str, ...]], ...] = (("rig relight (default)", ()),)


class Score(TypedDict):
    """One method's result on one (scene, dome, panorama)."""

    rel_rmse: float | None
    rel_rmse_object: float | None
    rel_rmse_base: float | None
    ratio: float | None
    ratio_object: float | None
    ratio_base: float | None
    seconds: float
    error: str
    note: str


Records = dict[str, dict[str, dict[str, dict[str, Score]]]]


def _methods(records: Records) -> list[str]:
    """Every method in the records, the sums and :data:`CLI_METHODS` first, in their order."""
    order = [SUM_FULL, SUM_UPPER, *(label for label, _ in (*CLI_METHODS, *SLOW_CLI_METHODS))]
    found = {m for domes in records.values() for panos in domes.values()
             for by_method in panos.values() for m in by_method}  # fmt: skip
    return [m for m in order if m in found] + sorted(found - set(order))


def _cell(by_method: dict[str, Score], method: str, key: Literal["rel_rmse", "rel_rmse_object"]
          ) -> str:  # fmt: skip
    return _fmt(by_method[method][key]) if method in by_method else "-"


def _fmt(value: float | None, percent: bool = True) -> str:
    if value is None:
        return "failed"
    return f"{100 * value:.1f} %" if percent else f"{value:.3f}"


def _mean(values: Sequence[float | None]) -> float | None:
    if not values or any(v is None for v in values):
        return None
    return float(np.mean([v for v in values if v is not None]))


def _panorama_mean(
    panos: dict[str, dict[str, Score]],
    method: str,
    key: Literal["rel_rmse", "rel_rmse_object", "rel_rmse_base", "ratio"],
) -> float | None:
    """A score's mean over the panoramas the method ran on (None when any run failed)."""
    return _mean([panos[p][method][key] for p in panos if method in panos[p]])


def format_tables(records: Records) -> str:
    """The Markdown report: means over panoramas, per panorama, and the white-sky base check.

    Parameters
    ----------
    records : scene -> dome (str) -> panorama -> method -> Score
    """
    methods = _methods(records)
    lines = ["## Relative RMSE, mean over panoramas", "",
             "| scene | dome | method | all | object | base | brightness | sum (full) | "
             "sum (upper) |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for scene, domes in records.items():
        for dome, panos in domes.items():
            full = _fmt(_panorama_mean(panos, SUM_FULL, "rel_rmse"))
            upper = _fmt(_panorama_mean(panos, SUM_UPPER, "rel_rmse"))
            for method in methods:
                errors = [_fmt(_panorama_mean(panos, method, key))
                         for key in ("rel_rmse", "rel_rmse_object", "rel_rmse_base")]  # fmt: skip
                ratio = _fmt(_panorama_mean(panos, method, "ratio"), percent=False)
                lines.append(
                    f"| {scene} | {dome} | {method} | {' | '.join(errors)} | {ratio} | {full} | "
                    f"{upper} |"
                )
    lines += ["", "## Relative RMSE per panorama (whole view)", "",
              "| scene | dome | panorama | " + " | ".join(methods) + " |",
              "|---|---|---|" + "---|" * len(methods)]  # fmt: skip
    for scene, domes in records.items():
        for dome, panos in domes.items():
            for pano, by_method in panos.items():
                cells = " | ".join(_cell(by_method, m, "rel_rmse") for m in methods)
                lines.append(f"| {scene} | {dome} | {pano} | {cells} |")
    lines += ["", "## Object only, per panorama", "",
              "| scene | dome | panorama | " + " | ".join(methods) + " |",
              "|---|---|---|" + "---|" * len(methods)]  # fmt: skip
    for scene, domes in records.items():
        for dome, panos in domes.items():
            for pano, by_method in panos.items():
                cells = " | ".join(_cell(by_method, m, "rel_rmse_object") for m in methods)
                lines.append(f"| {scene} | {dome} | {pano} | {cells} |")
    if any("white" in panos for domes in records.values() for panos in domes.values()):
        lines += ["", "## White sky: base brightness pred / truth", "",
                  "| scene | dome | " + " | ".join(methods) + " |",
                  "|---|---|" + "---|" * len(methods)]  # fmt: skip
        for scene, domes in records.items():
            for dome, panos in domes.items():
                if "white" in panos:
                    white = panos["white"]
                    cells = " | ".join(
                        _fmt(white[m]["ratio_base"], percent=False) if m in white else "-"
                        for m in methods
                    )
                    lines.append(f"| {scene} | {dome} | {cells} |")
    failures = [f"- {scene} {dome} {pano} {m}: {s['error']}"
                for scene, domes in records.items() for dome, panos in domes.items()
                for pano, by_method in panos.items() for m, s in by_method.items()
                if s["error"]]  # fmt: skip
    if failures:
        lines += ["", "## Failed runs", "", *failures]
    return "\n".join(lines) + "\n"


def chart(records: Records, path: Path) -> None:
    """Bars of the mean relative RMSE (whole view) per scene and dome, one bar per method."""
    methods = _methods(records)
    groups = [(scene, dome) for scene, domes in records.items() for dome in domes]
    figure, axes = plt.subplots(figsize=(max(8.0, 1.6 * len(groups)), 4.5))
    width = 0.8 / len(methods)
    palette = plt.get_cmap("tab20")  # more methods than the default cycle's ten colours
    for k, method in enumerate(methods):
        heights = []
        for scene, dome in groups:
            panos = records[scene][dome]
            value = _panorama_mean(panos, method, "rel_rmse")
            heights.append(np.nan if value is None else 100 * value)
        axes.bar(np.arange(len(groups)) + (k - 0.5 * (len(methods) - 1)) * width, heights,
                 width, label=method, color=palette(k % 20))  # fmt: skip
    axes.set_xticks(np.arange(len(groups)), [f"{s}\n{d} lights" for s, d in groups], fontsize=8)
    axes.set_ylabel("relative RMSE vs path-traced truth, %\n(mean over panoramas)")
    axes.legend(fontsize=7)
    axes.grid(axis="y", alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
