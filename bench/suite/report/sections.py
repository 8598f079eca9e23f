"""The sections of REPORT.md after its title, each computed from the results alone.

The run's context (the machine, what is measured), the accuracy studies
(:mod:`bench.suite.report.studies`), the fields, the product's speed, then the advisor's and the
stability study's sections, whose tables their modules format (:mod:`bench.advisor`,
:mod:`bench.stability`).
"""

from __future__ import annotations

from bench.advisor import format_advisor
from bench.guard_advice import format_advice
from bench.held_out import format_held_out
from bench.stability import format_stability
from bench.suite.report.markdown import markdown_table, ratio
from bench.suite.report.studies import study_sections
from bench.suite.results import ProductRecord, SuiteResults

__all__ = ["report_sections"]


def _section_machine(results: SuiteResults) -> list[str]:
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


def _section_method(results: SuiteResults) -> list[str]:
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


def _section_fields(results: SuiteResults) -> list[str]:
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
        *markdown_table(["scene", "S", "T", "points", "views", "radiance MB", "fit", "load"], rows),
    ]


def _section_product(results: SuiteResults) -> list[str]:
    # Results of a run that measured no part of the product have none.
    product: ProductRecord = results.get("product") or {}
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
            f"measured copy bandwidth ({loop['copy_bandwidth_GBps']:.1f} GB/s); the error of a "
            "frame against the same predictors with the panorama summed exactly (64 x 128), "
            "the price of each mode's lighting approximation (`default` is its own reference; "
            "`models, precomputed` is its interactive variant):",
            "",
        ]
        base = loop["modes"][0]
        lines += markdown_table(
            [
                "mode",
                "of a 30 fps frame",
                "new view / new lighting",
                "vs paper",
                "relight compute",
                "vs bandwidth floor",
                "error vs exact reference",
            ],
            [
                [
                    m["mode"],
                    f"{m['frame_budget_ratio']:.2f}",
                    ratio(m["loop_new_view_ms"], m["loop_new_lighting_ms"]),
                    ratio(m["loop_new_lighting_ms"], base["loop_new_lighting_ms"]),
                    f"{m['relight_compute_ms']:.1f} ms" if "relight_compute_ms" in m else "-",
                    f"{m['bandwidth_floor_ratio']:.1f}x" if "bandwidth_floor_ratio" in m else "-",
                    f"{m['error_vs_reference']:.2%}" if "error_vs_reference" in m else "-",
                ]
                for m in loop["modes"]
            ],
        )
    return [*lines, ""]


def _section_stability(results: SuiteResults) -> list[str]:
    if not results.get("stability"):
        return []
    return [
        "## Where methods fail (the stability study)",
        "",
        "Each failure case of `bench/stability.py` in a failing and a benign configuration, "
        "with the warnings `rig relight` prints for it (`render/guards/`).",
        "",
        format_stability(results["stability"]).rstrip("\n"),
        "",
    ]


def report_sections(results: SuiteResults, front: list[str]) -> list[str]:
    """Every section of REPORT.md after its title, as lines, in the report's order.

    Parameters
    ----------
    results : SuiteResults
    front : list of str, the Pareto front's labels, fastest first (the chain marks them)

    Returns
    -------
    list of str; a study without rows gives no section
    """
    lines = [
        *_section_machine(results),
        *_section_method(results),
        *study_sections(results, front),
        *_section_fields(results),
        *_section_product(results),
    ]
    if results.get("advisor"):
        lines += [format_advisor(results["advisor"]).rstrip("\n"), ""]
    held_out = results.get("held_out")
    if held_out:
        lines += [format_held_out(held_out).rstrip("\n"), "", "![held-out PSNR](held_out.png)", ""]
    if results.get("guard_advice"):
        lines += [
            "## Does the guards' advice help? (held-out lights)",
            "",
            format_advice(results["guard_advice"]).rstrip("\n"),
            "",
        ]
    return lines + _section_stability(results)
