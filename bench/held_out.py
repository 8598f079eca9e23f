"""The held-out-light study: every method predicting lights it never saw, on data of three kinds.

Each dataset is labelled by what it can say about a method (the issue's first rule: no method
judged where it is the truth):

``real``
    the bundled RTI capture (a bronze lion, 240 lights, 8-bit JPEG): nobody's model;
``path-traced``
    fields rendered by Mitsuba 3's path tracer of materials outside every fitted family
    (:mod:`sim.world.mitsuba`), when the study is given them;
``own family``
    the project's simulator, whose material *is* the lambert+ggx model: a figure only this
    kind supports says nothing about real objects, and the report says so.

Every dataset is scored by :func:`render.evaluation.evaluate` with every method of
:data:`render.light_prediction.PREDICTORS`; the records go to ``results.json`` under
``held_out`` and the report's section and chart come from them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, TypedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from core.directions import hemisphere_layout
from core.field_store import ReflectanceField
from core.sample_data import rti_capture_path
from processing.rti import open_field_or_rti
from render.evaluation import Evaluation, evaluate
from render.held_out_lights import test_field_from_lp
from render.light_prediction import PREDICTORS
from render.light_splits import split_lights
from sim.field import field_cameras, simulate_field
from sim.rti_capture import RtiSpec, make_world_rti
from sim.world.mitsuba import load_world, render_world_field

__all__ = [
    "WORLD_TEST_LIGHTS",
    "HeldOutRecord",
    "WorldSpec",
    "format_held_out",
    "held_out_chart",
    "held_out_record",
    "own_family_fields",
    "run_held_out",
    "world_fields",
    "world_rti_captures",
]

Family = Literal["real", "path-traced", "own family"]


class MethodScores(TypedDict):
    """One method's mean scores on one dataset (None: the method did not apply)."""

    psnr: float | None
    ssim: float | None
    delta_e: float | None
    rel_rmse: float | None
    seconds: float
    note: str


class HeldOutRecord(TypedDict):
    """One dataset and split, every method's means."""

    dataset: str
    family: Family
    split: str
    fit_lights: int
    test_lights: int
    cameras: int
    seconds: float
    methods: dict[str, MethodScores]


def held_out_record(
    dataset: str, family: Family, split: str, result: Evaluation, seconds: float
) -> HeldOutRecord:
    """The record of one evaluation."""
    methods: dict[str, MethodScores] = {}
    for m in result.methods:
        q = None if m.mean is None else m.mean.to_dict()
        methods[m.name] = {
            "psnr": None if q is None else q["psnr"],
            "ssim": None if q is None else q["ssim"],
            "delta_e": None if q is None else q["delta_e"],
            "rel_rmse": None if q is None else q["rel_rmse"],
            "seconds": m.seconds,
            "note": m.note,
        }
    return {
        "dataset": dataset,
        "family": family,
        "split": split,
        "fit_lights": result.fit_lights,
        "test_lights": result.test_lights,
        "cameras": result.cameras,
        "seconds": seconds,
        "methods": methods,
    }


def _timed(
    dataset: str,
    family: Family,
    split: str,
    fit: ReflectanceField,
    test: ReflectanceField,
    methods: Sequence[str],
) -> HeldOutRecord:
    start = time.perf_counter()
    result = evaluate(fit, test, methods)
    return held_out_record(dataset, family, split, result, time.perf_counter() - start)


#: A path-traced field of the study: (cameras, lights, image side, samples per pixel, points).
WorldSpec = tuple[int, int, int, int, int]
#: Test lights of a path-traced field: a grid, which never meets the fit lights' Fibonacci set.
WORLD_TEST_LIGHTS = 8


def world_fields(
    fields_dir: Path, names: Sequence[str], spec: WorldSpec
) -> list[tuple[str, Path, Path]]:
    """Render (once; cached in ``fields_dir``) the fit and test fields of each world.

    Parameters
    ----------
    fields_dir : Path, where the stores are kept between runs
    names : bundled worlds (:data:`sim.world.mitsuba.WORLDS`)
    spec : WorldSpec

    Returns
    -------
    list of (name, fit store, test store)
    """
    cameras, lights, side, spp, points = spec
    views = field_cameras(cameras, width=side, height=side)
    made = []
    for name in names:
        world = load_world(name)
        stem = fields_dir / f"world-{name}-{cameras}x{lights}-{side}px-{spp}spp-{points}"
        fit, test = stem.with_suffix(".zarr"), stem.with_name(stem.name + "-test.zarr")
        if not fit.exists():
            render_world_field(
                fit, world, lights=lights, cameras=views, points=points, spp=spp, layout="fibonacci"
            )
        if not test.exists():
            render_world_field(
                test,
                world,
                lights=hemisphere_layout(WORLD_TEST_LIGHTS, "grid"),
                cameras=views,
                points=points,
                spp=spp,
            )
        made.append((name, fit, test))
    return made


def world_rti_captures(
    fields_dir: Path, names: Sequence[str], spec: RtiSpec
) -> list[tuple[str, Path, Path]]:
    """Make (once; cached in ``fields_dir``) an RTI capture of each world: (name, fit, test)."""
    made = []
    for name in names:
        fit_count, test_count, width, height, spp = spec
        folder = fields_dir / f"rti-{name}-{fit_count}+{test_count}-{width}x{height}-{spp}spp"
        if not (folder / "test.lp").is_file():
            make_world_rti(folder, name, spec)
        made.append((name, folder / "fit.lp", folder / "test.lp"))
    return made


#: Splits of the real capture: interleaved, whole rings unseen, and random halves.
REAL_SPLITS = ("every-other", "rings", "random:0")


def run_held_out(
    fields_dir: Path,
    *,
    quick: bool,
    worlds: Sequence[tuple[str, Path, Path]] = (),
    rti_worlds: Sequence[tuple[str, Path, Path]] = (),
    methods: Sequence[str] = PREDICTORS,
) -> list[HeldOutRecord]:
    """Evaluate every method on the real capture, the given path-traced fields and the simulator.

    Parameters
    ----------
    fields_dir : Path, where the simulator's fields are made once and reused
    quick : bool, one split of the real capture and a smaller simulated field
    worlds : (name, fit store, test store) of path-traced fields (same views, other lights)
    rti_worlds : (name, fit .lp, test .lp) of path-traced RTI captures
    methods : names of :data:`render.light_prediction.PREDICTORS`

    Returns
    -------
    list of HeldOutRecord, real first, then path-traced, then the simulator's own family
    """
    records: list[HeldOutRecord] = []
    with open_field_or_rti(rti_capture_path()) as capture:
        for split in REAL_SPLITS[:1] if quick else REAL_SPLITS:
            fit_index, test_index = split_lights(capture, split)
            fit, test = capture.subset(lights=fit_index), capture.subset(lights=test_index)
            records.append(_timed("RTI lion (bundled)", "real", split, fit, test, methods))
    for name, fit_lp, test_lp in rti_worlds:
        with open_field_or_rti(fit_lp) as fit:
            test = test_field_from_lp(test_lp)
            records.append(_timed(f"{name} (RTI dome)", "path-traced", "other lights", fit,
                                  test, methods))  # fmt: skip
    for name, fit_path, test_path in worlds:
        fit, test = ReflectanceField.open(fit_path), ReflectanceField.open(test_path)
        records.append(_timed(name, "path-traced", "other lights", fit, test, methods))
    for name, fit_path, test_path in own_family_fields(fields_dir, quick=quick):
        fit, test = ReflectanceField.open(fit_path), ReflectanceField.open(test_path)
        records.append(_timed(name, "own family", "other lights", fit, test, methods))
    return records


def own_family_fields(fields_dir: Path, *, quick: bool) -> list[tuple[str, Path, Path]]:
    """Simulate (once; cached in ``fields_dir``) the glossy sphere's fit and test fields.

    Returns
    -------
    list of (name, fit store, test store); the simulator's material is the lambert+ggx model
    """
    cameras, lights, points = (6, 30, 3000) if quick else (12, 30, 8000)
    views = field_cameras(cameras, width=64, height=64)
    fit_path = fields_dir / f"held-out-glossy-sphere-{cameras}x{lights}-{points}.zarr"
    test_path = fields_dir / f"held-out-glossy-sphere-{cameras}x{lights}-{points}-test.zarr"
    if not fit_path.exists():
        simulate_field(fit_path, "glossy-sphere", lights=lights, cameras=views, points=points,
                       layout="fibonacci")  # fmt: skip
    if not test_path.exists():
        # Between the fit lights: a grid against a Fibonacci lattice never coincides.
        simulate_field(test_path, "glossy-sphere", lights=hemisphere_layout(10, "grid"),
                       cameras=views, points=points)  # fmt: skip
    return [("glossy sphere (simulator)", fit_path, test_path)]


def _psnr(scores: MethodScores) -> float:
    """A method's PSNR for ranking: inf when exact, -inf when it did not apply."""
    if scores["ssim"] is None:
        return -math.inf
    return math.inf if scores["psnr"] is None else float(scores["psnr"])


def _value(scores: MethodScores, key: str) -> float:
    value = scores.get(key)
    return float(value) if isinstance(value, int | float) else math.nan


def format_held_out(records: Sequence[HeldOutRecord]) -> str:
    """The report's section: per dataset, every method's means, best PSNR first."""
    lines = [
        "## Held-out lights (every method, lights it never saw)",
        "",
        "Each method predicts the test lights from the fit lights alone (`rig evaluate`); "
        "PSNR and SSIM on 8-bit sRGB, mean CIEDE2000, relative RMSE in linear light, means "
        "over the test images. *real*: the bundled RTI capture; *path-traced*: Mitsuba 3 "
        "renders of materials outside every fitted family; *own family*: the project's "
        "simulator, whose material is the lambert+ggx model itself (its figures say nothing "
        "about real objects).",
        "",
    ]
    for record in records:
        rbf = _value(record["methods"]["rbf"], "psnr") if "rbf" in record["methods"] else math.nan
        lines += [
            f"### {record['dataset']}: {record['family']}, split {record['split']}",
            "",
            f"{record['test_lights']} test lights from {record['fit_lights']}, "
            f"{record['cameras']} camera{'s' if record['cameras'] != 1 else ''}; "
            f"{record['seconds']:.0f} s for every method.",
            "",
            "| method | PSNR (dB) | vs rbf (dB) | SSIM | ΔE2000 | rel. RMSE | s |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        ranked = sorted(record["methods"].items(), key=lambda kv: -_psnr(kv[1]))
        for name, scores in ranked:
            if scores["ssim"] is None:  # not applicable (the note says why)
                lines.append(f"| {name} | {scores['note']} | | | | | |")
                continue
            psnr = _psnr(scores)
            lines.append(
                f"| {name} | {psnr:.2f} | {psnr - rbf:+.2f} | {_value(scores, 'ssim'):.4f} | "
                f"{_value(scores, 'delta_e'):.2f} | {_value(scores, 'rel_rmse'):.1%} | "
                f"{scores['seconds']:.1f} |"
            )
        lines.append("")
    return "\n".join(lines)


def held_out_chart(records: Sequence[HeldOutRecord], path: Path) -> None:
    """PSNR of every method on every dataset (one panel per dataset), baselines marked."""
    if not records:
        return
    fig, axes = plt.subplots(len(records), 1, figsize=(9, 2.2 * len(records) + 0.6),
                             squeeze=False)  # fmt: skip
    baselines = {"nearest", "barycentric", "rbf", "ptm", "hsh2", "hsh3", "ptm-8bit",
                 "hsh2-8bit", "hsh3-8bit"}  # fmt: skip
    for ax, record in zip(axes[:, 0], records, strict=True):
        names = [n for n in record["methods"] if math.isfinite(_psnr(record["methods"][n]))]
        values = [_psnr(record["methods"][n]) for n in names]
        if not values:
            continue
        colours = ["#999999" if n in baselines else "#c0392b" for n in names]
        ax.bar(np.arange(len(names)), values, color=colours)
        ax.set_xticks(np.arange(len(names)), names, rotation=30, ha="right", fontsize=7)
        ax.set_ylim(min(values) - 2.0, max(values) + 1.0)
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(f"{record['dataset']} ({record['family']}, {record['split']})", fontsize=9)
    fig.suptitle("Held-out lights: grey = baselines RTI users have, red = the project's rungs")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
