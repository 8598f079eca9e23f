"""REPORT.md and the charts of the speed-against-accuracy suite, from its results alone.

:func:`write_report` reads nothing but the results dict (``results.json`` of
:mod:`bench.suite`), so a report can be regenerated, or extended with other modules' sections
(``extra_sections``), without running anything again.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from bench.advisor import advisor_chart, format_advisor
from bench.stability import format_stability

__all__ = [
    "CHARTS",
    "aggregate",
    "chain_rows",
    "pareto_front",
    "write_report",
]

Row = dict[str, Any]

#: The charts :func:`write_report` draws, file name to caption.
CHARTS = {
    "pareto.png": "error against time per new lighting",
    "error_vs_k.png": "error against K",
    "error_vs_density.png": "error against field density",
    "ldr_vs_hdr.png": "LDR against HDR panoramas",
}


def _mean(values: Iterable[float | None]) -> float:
    kept = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(kept)) if kept else float("nan")


def aggregate(
    rows: Sequence[Row],
    metric: str,
    *,
    view: str | None = None,
    ldr: bool | None = False,
    environment: str | None = None,
) -> float:
    """Mean of a score over rows (scenes) and their scores (environments, views).

    ``view`` None takes both views; ``ldr`` None takes HDR and LDR environments.
    """
    return _mean(
        s[metric]
        for r in rows
        for s in r["scores"]
        if (view is None or s["view"] == view)
        and (ldr is None or s["ldr"] == ldr)
        and (environment is None or s["environment"] == environment)
    )


def _timing(rows: Sequence[Row], key: str) -> float:
    return _mean(r[key] for r in rows)


def chain_rows(results: dict[str, Any]) -> dict[str, list[Row]]:
    """The ablation rows on the chain field, by method label in chain order."""
    out: dict[str, list[Row]] = {label: [] for label in results["chain"]}
    for r in results["rows"]:
        if r["study"] == "ablation":
            out[r["label"]].append(r)
    return {label: rows for label, rows in out.items() if rows}


def _k_rows(results: dict[str, Any]) -> dict[str, dict[int, list[Row]]]:
    out: dict[str, dict[int, list[Row]]] = {}
    for r in results["rows"]:
        if r["study"] == "k":
            out.setdefault(r["family"], {}).setdefault(r["k"], []).append(r)
    return {family: dict(sorted(by_k.items())) for family, by_k in out.items()}


def _density_rows(results: dict[str, Any]) -> dict[str, dict[tuple[int, int, int], list[Row]]]:
    """Rows of the density methods by label and field (S, T, points); the chain field too."""
    out: dict[str, dict[tuple[int, int, int], list[Row]]] = {
        label: {} for label in results["density_methods"]
    }
    for r in results["rows"]:
        if r["label"] in out and r["study"] in ("ablation", "density"):
            out[r["label"]].setdefault((r["S"], r["T"], r["points"]), []).append(r)
    return {
        label: dict(sorted(by_field.items(), key=lambda item: (item[0][1], item[0][0])))
        for label, by_field in out.items()
        if by_field
    }


def pareto_front(points: dict[str, tuple[float, float]]) -> list[str]:
    """The labels no other point beats in both time and error, fastest first."""
    ordered = sorted(points, key=lambda label: (points[label][0], points[label][1]))
    front: list[str] = []
    best = math.inf
    for label in ordered:
        error = points[label][1]
        if error < best:
            front.append(label)
            best = error
    return front


def _pct(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.2%}"


def _db(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.1f}"


def _ratio(value: float, reference: float) -> str:
    if not (math.isfinite(value) and math.isfinite(reference)) or reference <= 0:
        return "-"
    return f"{value / reference:.2f}x"


def _field_name(field: tuple[int, int, int]) -> str:
    cameras, lights, points = field
    return f"S={cameras} T={lights} ({points // 1000}k pts)"


def _table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return [*lines, ""]


def _environment_names(results: dict[str, Any], *, ldr: bool | None = None) -> list[str]:
    return [
        name for name, env in results["environments"].items() if ldr is None or env["ldr"] == ldr
    ]


# --- charts -----------------------------------------------------------------------------------


def _pareto_points(results: dict[str, Any]) -> dict[str, tuple[float, float]]:
    """Mean time per new lighting and mean HDR error of every method on the chain field."""
    by_label: dict[str, list[Row]] = {}
    cameras, lights = results["chain_field"][:2]
    for r in results["rows"]:
        if r["study"] in ("ablation", "k") and (r["S"], r["T"]) == (cameras, lights):
            by_label.setdefault(r["label"], []).append(r)
    return {
        label: (_timing(rows, "new_lighting_ms"), aggregate(rows, "relative_rmse"))
        for label, rows in by_label.items()
    }


def _chart_pareto(results: dict[str, Any], path: Path) -> list[str]:
    points = _pareto_points(results)
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


def _chart_k(results: dict[str, Any], path: Path) -> None:
    figure, axis = plt.subplots(figsize=(7, 4.5))
    for family, by_k in _k_rows(results).items():
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


def _chart_density(results: dict[str, Any], path: Path) -> None:
    figure, axis = plt.subplots(figsize=(7, 4.5))
    density = _density_rows(results)
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
    axis.set_xticks(range(len(fields)), [_field_name(f) for f in fields], fontsize=7)
    axis.set_yscale("log")
    axis.set_xlabel("field (S cameras, T lights)")
    axis.set_ylabel("relative RMSE, %, between view (log)")
    axis.set_title("Error against field density")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _ldr_pairs(results: dict[str, Any]) -> list[tuple[str, str]]:
    """(HDR, LDR) environment name pairs present in the results."""
    envs = results["environments"]
    return [
        (env["truth"], name) for name, env in envs.items() if env["ldr"] and env["truth"] in envs
    ]


def _chart_ldr(results: dict[str, Any], path: Path) -> None:
    pairs = _ldr_pairs(results)
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


# --- sections ---------------------------------------------------------------------------------


def _section_machine(results: dict[str, Any]) -> list[str]:
    m = results["machine"]
    load = ", ".join(f"{v:.2f}" for v in m["load_average"])
    return [
        "## Machine",
        "",
        f"{m['cpu_count']} cores ({m['processor']}, {m['platform']}), load average at the start "
        f"{load}, at the end {', '.join(f'{v:.2f}' for v in m.get('load_average_end', []))}; "
        f"Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}, OpenCV {m['opencv']}. "
        f"Peak resident memory of the run {m.get('peak_rss_MB', float('nan')):.0f} MB. "
        f"Whole run: {results.get('wall_s', float('nan')) / 60:.1f} min "
        f"({results['config']['name']} configuration). Absolute times on a shared "
        f"{m['cpu_count']}-core machine are noisy: read the ratios, all measured in this run.",
        "",
    ]


def _section_method(results: dict[str, Any]) -> list[str]:
    cameras, lights, points, size = results["chain_field"]
    envs = results["environments"]
    env_text = "; ".join(f"{name}: {env['source']}" for name, env in envs.items())
    scenes = list(dict.fromkeys(r["scene"] for r in results["rows"]))
    return [
        "## What is measured",
        "",
        f"Scenes: {', '.join(scenes)} (the simulator's; ground truth is direct illumination "
        "from a 64 x 128 pre-filter of the panorama, with shadows for the non-convex scene). "
        f"Environments: {env_text}. An LDR photo is scored against the ground truth of the "
        "HDR scene it was taken of.",
        "",
        f"The ablation chain and the K sweep use an S = {cameras}, T = {lights} field of "
        f"{points} points seen in {size} x {size} views. Each step of the chain adds one change "
        "to the step before; indented labels (branches) are alternatives to the step above "
        "them, not carried on. Views: a captured camera and a view halfway in azimuth between "
        "two captured cameras.",
        "",
        "- Relative RMSE: over the pixels both the relit image and the truth cover; PSNR "
        "against the truth's peak there.",
        f"- SSIM: {results['ssim']}.",
        "- Precompute: opening the engine; for per-sample models, loading their saved fit too "
        "(the fit itself is in the table of fields when this run made it).",
        "- Time per new lighting: set_lighting of a rotated panorama + render; per new view: "
        "set_view of a turned camera + render (medians after a warm-up frame).",
        f"- Memory: {results['memory']}.",
        "",
    ]


def _section_chain(results: dict[str, Any], front: list[str]) -> list[str]:
    chain = chain_rows(results)
    if not chain:
        return []
    base = chain.get("paper") or next(iter(chain.values()))
    base_label = "paper" if "paper" in chain else next(iter(chain))
    lines = [
        "## The ablation chain",
        "",
        "Means over the scenes and the HDR environments. Times and memory are ratios to the "
        f"paper's configuration ({base_label}: new lighting "
        f"{_timing(base, 'new_lighting_ms'):.1f} ms, new view "
        f"{_timing(base, 'new_view_ms'):.1f} ms, memory {_timing(base, 'memory_MB'):.1f} MB); "
        "precompute in milliseconds, since the interpolating engine defers its work to the first "
        "frame and opens in next to no time.",
        "",
    ]
    rows = []
    for label, group in chain.items():
        rows.append(
            [
                ("↳ " if group[0]["role"] == "branch" else "")
                + label
                + (" (Pareto)" if label in front else ""),
                _pct(aggregate(group, "relative_rmse", view="captured")),
                _pct(aggregate(group, "relative_rmse", view="between")),
                _db(aggregate(group, "psnr_db", view="between")),
                f"{aggregate(group, 'ssim', view='between'):.3f}",
                f"{1e3 * _timing(group, 'precompute_s'):.1f} ms",
                _ratio(_timing(group, "new_lighting_ms"), _timing(base, "new_lighting_ms")),
                _ratio(_timing(group, "new_view_ms"), _timing(base, "new_view_ms")),
                _ratio(_timing(group, "memory_MB"), _timing(base, "memory_MB")),
            ]
        )
    lines += _table(
        [
            "method",
            "rel. RMSE captured",
            "rel. RMSE between",
            "PSNR dB between",
            "SSIM between",
            "precompute",
            "new lighting",
            "new view",
            "memory",
        ],
        rows,
    )
    envs = _environment_names(results)
    for scene in dict.fromkeys(r["scene"] for group in chain.values() for r in group):
        lines += [
            f"{scene}: relative RMSE at the between view (captured view in parentheses)",
            "",
        ]
        table = []
        for label, group in chain.items():
            mine = [r for r in group if r["scene"] == scene]
            table.append(
                [label]
                + [
                    f"{_pct(aggregate(mine, 'relative_rmse', view='between', ldr=None, environment=e))}"  # noqa: E501
                    f" ({_pct(aggregate(mine, 'relative_rmse', view='captured', ldr=None, environment=e))})"  # noqa: E501
                    for e in envs
                ]
            )
        lines += _table(["method", *envs], table)
    return lines


def _section_pareto(results: dict[str, Any], front: list[str]) -> list[str]:
    points = _pareto_points(results)
    if not points:
        return []
    fastest = min(points, key=lambda label: points[label][0])
    best = min(points, key=lambda label: points[label][1])
    lines = [
        "## Error against time per frame (Pareto chart)",
        "",
        "![Pareto chart](pareto.png)",
        "",
        f"On the Pareto front, fastest first: {', '.join(front)}. The fastest method is "
        f"{fastest} ({points[fastest][0]:.1f} ms per new lighting, {_pct(points[fastest][1])}); "
        f"the most accurate is {best} ({_pct(points[best][1])}, "
        f"{_ratio(points[best][0], points[fastest][0])} the fastest's time).",
    ]
    if "paper" in points:
        ms, error = points["paper"]
        beaten = [
            label
            for label, (other_ms, other_error) in points.items()
            if other_ms <= ms and other_error < error
        ]
        lines[-1] += (
            " The paper's configuration is on the front."
            if "paper" in front
            else f" The paper's configuration is not on the front: {len(beaten)} method(s) are "
            f"both faster and more accurate (e.g. {', '.join(beaten[:3])})."
        )
    return [*lines, ""]


def _section_k(results: dict[str, Any]) -> list[str]:
    families = _k_rows(results)
    if not families:
        return []
    ks = sorted({k for by_k in families.values() for k in by_k})
    lines = [
        "## Error against K",
        "",
        "Relative RMSE at the between view (mean of scenes and HDR environments); time per new "
        "lighting as a ratio to the same family at the smallest K.",
        "",
    ]
    table = []
    readings = []
    for family, by_k in families.items():
        errors = {k: aggregate(rows, "relative_rmse", view="between") for k, rows in by_k.items()}
        first = min(by_k)
        table.append(
            [family]
            + [
                f"{_pct(errors[k])} ({_ratio(_timing(by_k[k], 'new_lighting_ms'), _timing(by_k[first], 'new_lighting_ms'))})"  # noqa: E501
                if k in by_k
                else "-"
                for k in ks
            ]
        )
        best_error = min(errors.values())
        enough = min(k for k, e in errors.items() if e <= 1.1 * best_error)
        readings.append(
            f"{family}: {_pct(errors[first])} at K = {first}, best {_pct(best_error)}; K = "
            f"{enough} is within 10 % of the best"
        )
    lines += _table(["family", *(f"K={k}" for k in ks)], table)
    lines += ["![error against K](error_vs_k.png)", "", "; ".join(readings) + ".", ""]
    return lines


def _section_density(results: dict[str, Any]) -> list[str]:
    density = _density_rows(results)
    if not density:
        return []
    fields = sorted(
        {f for by_field in density.values() for f in by_field}, key=lambda f: (f[1], f[0])
    )
    lines = [
        "## Error against field density",
        "",
        "Relative RMSE at the between view (captured in parentheses), mean of scenes and HDR "
        "environments. Fields differ in points and view size where the table of fields says so.",
        "",
    ]
    table = []
    readings = []
    for label, by_field in density.items():
        table.append(
            [label]
            + [
                f"{_pct(aggregate(by_field[f], 'relative_rmse', view='between'))} "
                f"({_pct(aggregate(by_field[f], 'relative_rmse', view='captured'))})"
                if f in by_field
                else "-"
                for f in fields
            ]
        )
        errors = {
            f: aggregate(rows, "relative_rmse", view="between") for f, rows in by_field.items()
        }
        sparse, dense = (
            min(errors, key=lambda f: f[0] * f[1]),
            max(errors, key=lambda f: f[0] * f[1]),
        )
        if sparse != dense:
            readings.append(
                f"{label}: {_pct(errors[sparse])} at {_field_name(sparse)} to "
                f"{_pct(errors[dense])} at {_field_name(dense)} "
                + (
                    f"({_ratio(errors[sparse], errors[dense])} less error on the denser field)"
                    if errors[dense] <= errors[sparse]
                    else f"({_ratio(errors[dense], errors[sparse])} more error on the denser field)"
                )
            )
    lines += _table(["method", *(_field_name(f) for f in fields)], table)
    lines += ["![error against field density](error_vs_density.png)", ""]
    if readings:
        lines += ["; ".join(readings) + ".", ""]
    return lines


def _section_ldr(results: dict[str, Any]) -> list[str]:
    pairs = _ldr_pairs(results)
    chain = chain_rows(results)
    if not pairs or not chain:
        return []
    lines = [
        "## LDR against HDR",
        "",
        "Relative RMSE against the HDR ground truth when the lighting is the HDR panorama and "
        "when it is its LDR photo (mean of scenes, both views), and the ratio LDR / HDR.",
        "",
    ]
    header = ["method"]
    for hdr, ldr in pairs:
        header += [hdr, ldr, "ratio"]
    table = []
    ratios: dict[str, list[float]] = {}
    for label, group in chain.items():
        cells = [label]
        for hdr, ldr in pairs:
            h = aggregate(group, "relative_rmse", ldr=None, environment=hdr)
            low = aggregate(group, "relative_rmse", ldr=None, environment=ldr)
            cells += [_pct(h), _pct(low), _ratio(low, h)]
            ratios.setdefault(hdr, []).append(low / h if h > 0 else float("nan"))
        table.append(cells)
    lines += _table(header, table)
    worst = max(ratios, key=lambda name: _mean(ratios[name]))
    readings = "; ".join(
        f"{name}: the LDR photo multiplies the error by {_mean(values):.1f} on average"
        for name, values in ratios.items()
    )
    lines += [
        "![LDR against HDR](ldr_vs_hdr.png)",
        "",
        f"{readings}. The LDR photo costs most under {worst}: no method recovers the light the "
        "clipping removed.",
        "",
    ]
    return lines


def _section_fields(results: dict[str, Any]) -> list[str]:
    rows = [
        [
            f["scene"],
            str(f["S"]),
            str(f["T"]),
            str(f["points"]),
            f"{f['image']} px",
            f"{f['field_MB']:.0f}",
            "-" if f["models_fit_s"] is None else f"{f['models_fit_s']:.1f} s",
            f"{f['models_load_s']:.2f} s",
        ]
        for f in results["fields"]
    ]
    return [
        "## Fields",
        "",
        "Per-sample model fits: the fit's time when it was made (fits are saved beside the field "
        "and loaded afterwards), and the load's.",
        "",
        *_table(["scene", "S", "T", "points", "views", "radiance MB", "fit", "load"], rows),
    ]


def _section_product(results: dict[str, Any]) -> list[str]:
    product = results.get("product") or {}
    if not product:
        return []
    cores = results["machine"]["cpu_count"]
    lines = ["## Speed of the whole product", "", f"One run on this {cores}-core machine.", ""]
    capture = product.get("capture")
    if capture:
        share = capture["controller_share_of_motion_and_exposure"]
        verdict = "meets" if share <= 0.02 else "misses"
        lines += [
            f"- Capture on the simulated rig ({capture['images']} images, "
            f"{capture['cameras']} cameras x {capture['lights']} lights): the controller's own "
            f"time is {share:.2%} of motion + exposure ({verdict} the 2 % goal); the simulated "
            f"camera's rendering, which a real camera spends exposing, is excluded.",
            "- Field building (`rig process` on that dataset): "
            f"{capture['process_over_capture']:.3f} s of processing per second of capture "
            f"({capture['process_images_per_s']:.1f} images per second).",
        ]
    loop = product.get("loop")
    if loop:
        lines += [
            f"- Interactive loop ({loop['scene']}, S={loop['S']} T={loop['T']}, {loop['points']} "
            f"points, {loop['image']} px view): time per new lighting (preparing the lighting and "
            "rendering) as a share of a 30 fps frame, and, for the interpolating engines, the "
            "relighting compute against its floor, one read of the view's blended field at the "
            f"measured copy bandwidth ({loop['copy_bandwidth_GBps']:.1f} GB/s):",
            "",
        ]
        base = loop["modes"][0]
        lines += _table(
            [
                "mode",
                "of a 30 fps frame",
                "new view / new lighting",
                "vs paper",
                "relight compute",
                "vs bandwidth floor",
            ],
            [
                [
                    m["mode"],
                    f"{m['frame_budget_ratio']:.2f}",
                    _ratio(m["loop_new_view_ms"], m["loop_new_lighting_ms"]),
                    _ratio(m["loop_new_lighting_ms"], base["loop_new_lighting_ms"]),
                    f"{m['relight_compute_ms']:.1f} ms" if "relight_compute_ms" in m else "-",
                    f"{m['bandwidth_floor_ratio']:.1f}x" if "bandwidth_floor_ratio" in m else "-",
                ]
                for m in loop["modes"]
            ],
        )
    return [*lines, ""]


def write_report(
    results: dict[str, Any], directory: Path, extra_sections: Sequence[str] | None = None
) -> Path:
    """Draw the charts and write ``directory/REPORT.md`` from the suite's results.

    Parameters
    ----------
    results : dict, as :func:`bench.suite.run_suite` returns it (or results.json read back)
    directory : Path, where the charts and REPORT.md go
    extra_sections : sequence of str, optional
        Markdown sections of other studies (each starting with its own ``## `` heading),
        appended after the suite's own, in order.

    Returns
    -------
    Path of REPORT.md
    """
    directory.mkdir(parents=True, exist_ok=True)
    front = _chart_pareto(results, directory / "pareto.png")
    charts: list[tuple[str, Callable[[dict[str, Any], Path], None]]] = [
        ("error_vs_k.png", _chart_k),
        ("error_vs_density.png", _chart_density),
        ("ldr_vs_hdr.png", _chart_ldr),
    ]
    for name, draw in charts:
        draw(results, directory / name)
    lines = [
        "# Relighting: speed against accuracy",
        "",
        "Generated from results.json by `bench.report.write_report`; every figure below was "
        "measured in the same run.",
        "",
        *_section_machine(results),
        *_section_method(results),
        *_section_chain(results, front),
        *_section_pareto(results, front),
        *_section_k(results),
        *_section_density(results),
        *_section_ldr(results),
        *_section_fields(results),
        *_section_product(results),
    ]
    if results.get("advisor"):
        advisor_chart(results["advisor"], directory / "advisor.png")
        lines += [format_advisor(results["advisor"]).rstrip("\n"), ""]
    if results.get("stability"):
        lines += [
            "## Where methods fail (the stability study)",
            "",
            "Each failure case of `bench/stability.py` in a failing and a benign configuration, "
            "with the warnings `rig relight` prints for it (`render/guards.py`).",
            "",
            format_stability(results["stability"]).rstrip("\n"),
            "",
        ]
    for section in extra_sections or ():
        lines += [section.rstrip("\n"), ""]
    path = directory / "REPORT.md"
    path.write_text("\n".join(lines).rstrip("\n") + "\n")
    return path
