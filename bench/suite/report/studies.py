"""The report's sections on the accuracy studies, each computed from the results alone.

The ablation chain, the Pareto front, error against K, against field density, and LDR against
HDR panoramas; the charts they show are drawn by :mod:`bench.suite.report.charts`.
"""

from __future__ import annotations

from collections.abc import Sequence

from bench.suite.report.aggregate import (
    aggregate,
    chain_rows,
    density_rows,
    environment_names,
    field_label,
    finite_mean,
    k_rows,
    ldr_pairs,
    mean_figure,
    pareto_points,
)
from bench.suite.report.markdown import decibels, markdown_table, percent, ratio
from bench.suite.results import Row, SuiteResults

__all__ = ["study_sections"]


def _between_and_captured(
    rows: Sequence[Row], *, ldr: bool | None = False, environment: str | None = None
) -> str:
    """Relative RMSE at the between view, and at the captured view in parentheses."""
    between = aggregate(rows, "relative_rmse", view="between", ldr=ldr, environment=environment)
    captured = aggregate(rows, "relative_rmse", view="captured", ldr=ldr, environment=environment)
    return f"{percent(between)} ({percent(captured)})"


def _section_chain(results: SuiteResults, front: list[str]) -> list[str]:
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
        f"{mean_figure(base, 'new_lighting_ms'):.1f} ms, new view "
        f"{mean_figure(base, 'new_view_ms'):.1f} ms, memory "
        f"{mean_figure(base, 'memory_MB'):.1f} MB); "
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
                percent(aggregate(group, "relative_rmse", view="captured")),
                percent(aggregate(group, "relative_rmse", view="between")),
                decibels(aggregate(group, "psnr_db", view="between")),
                f"{aggregate(group, 'ssim', view='between'):.3f}",
                f"{1e3 * mean_figure(group, 'precompute_s'):.1f} ms",
                ratio(mean_figure(group, "new_lighting_ms"), mean_figure(base, "new_lighting_ms")),
                ratio(mean_figure(group, "new_view_ms"), mean_figure(base, "new_view_ms")),
                ratio(mean_figure(group, "memory_MB"), mean_figure(base, "memory_MB")),
            ]
        )
    lines += markdown_table(
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
    envs = environment_names(results)
    for scene in dict.fromkeys(r["scene"] for group in chain.values() for r in group):
        lines += [
            f"{scene}: relative RMSE at the between view (captured view in parentheses)",
            "",
        ]
        table = []
        for label, group in chain.items():
            mine = [r for r in group if r["scene"] == scene]
            table.append(
                [label] + [_between_and_captured(mine, ldr=None, environment=e) for e in envs]
            )
        lines += markdown_table(["method", *envs], table)
    return lines


def _section_pareto(results: SuiteResults, front: list[str]) -> list[str]:
    points = pareto_points(results)
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
        f"{fastest} ({points[fastest][0]:.1f} ms per new lighting, {percent(points[fastest][1])}); "
        f"the most accurate is {best} ({percent(points[best][1])}, "
        f"{ratio(points[best][0], points[fastest][0])} the fastest's time).",
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


def _section_k(results: SuiteResults) -> list[str]:
    families = k_rows(results)
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
                f"{percent(errors[k])} ({ratio(mean_figure(by_k[k], 'new_lighting_ms'), mean_figure(by_k[first], 'new_lighting_ms'))})"  # noqa: E501
                if k in by_k
                else "-"
                for k in ks
            ]
        )
        best_error = min(errors.values())
        enough = min(k for k, e in errors.items() if e <= 1.1 * best_error)
        readings.append(
            f"{family}: {percent(errors[first])} at K = {first}, best {percent(best_error)}; K = "
            f"{enough} is within 10 % of the best"
        )
    lines += markdown_table(["family", *(f"K={k}" for k in ks)], table)
    lines += ["![error against K](error_vs_k.png)", "", "; ".join(readings) + ".", ""]
    return lines


def _section_density(results: SuiteResults) -> list[str]:
    density = density_rows(results)
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
            [label] + [_between_and_captured(by_field[f]) if f in by_field else "-" for f in fields]
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
                f"{label}: {percent(errors[sparse])} at {field_label(sparse)} to "
                f"{percent(errors[dense])} at {field_label(dense)} "
                + (
                    f"({ratio(errors[sparse], errors[dense])} less error on the denser field)"
                    if errors[dense] <= errors[sparse]
                    else f"({ratio(errors[dense], errors[sparse])} more error on the denser field)"
                )
            )
    lines += markdown_table(["method", *(field_label(f) for f in fields)], table)
    lines += ["![error against field density](error_vs_density.png)", ""]
    if readings:
        lines += ["; ".join(readings) + ".", ""]
    return lines


def _section_ldr(results: SuiteResults) -> list[str]:
    pairs = ldr_pairs(results)
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
            cells += [percent(h), percent(low), ratio(low, h)]
            ratios.setdefault(hdr, []).append(low / h if h > 0 else float("nan"))
        table.append(cells)
    lines += markdown_table(header, table)
    worst = max(ratios, key=lambda name: finite_mean(ratios[name]))
    readings = "; ".join(
        f"{name}: the LDR photo multiplies the error by {finite_mean(values):.1f} on average"
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


def study_sections(results: SuiteResults, front: list[str]) -> list[str]:
    """The sections of the ablation chain, the Pareto front, K, density and LDR, as lines.

    Parameters
    ----------
    results : SuiteResults
    front : list of str, the Pareto front's labels, fastest first (the chain marks them)

    Returns
    -------
    list of str; a study without rows gives no section
    """
    return [
        *_section_chain(results, front),
        *_section_pareto(results, front),
        *_section_k(results),
        *_section_density(results),
        *_section_ldr(results),
    ]
