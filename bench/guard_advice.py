"""Do the guards' advice help where they fire? Measured on lights no method saw.

Every guard of :mod:`render.guards` that may advise relighting through the per-sample models
(ghosting, sun, noise, views) is run on a fit field with an interpolating mode, under a sunny
sky and under the courtyard. Where one fires, the study scores on the test lights (which
neither the fit nor the advice saw; a test light is a sun of its own):

``in use``
    the interpolation the mode used (barycentric);
``old advice``
    the models, which the guards advised unconditionally before;
``new advice``
    what the guard advises now: the models only where the field's own held-out comparison
    (:class:`render.engines.modes.HeldOutComparison`, every other fit light held out) found
    them better, else to keep interpolating and capture more.

Datasets are labelled as in :mod:`bench.held_out`: the real capture, path-traced RTI domes and
fields (materials no model contains), and the simulator (its material is the lambert+ggx
model: its figures say nothing about real objects).

``python -m bench.guard_advice -o DIR [--quick] [--fields DIR]`` writes ``guard_advice.json``
and ``guard_advice.md`` (by default on the data of ``rig bench --quick``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from core.field_store import ReflectanceField
from core.sample_data import panorama_path, rti_capture_path
from processing.panorama import read_panorama
from processing.rti import open_field_or_rti
from processing.sample_models import fit_sample_models
from render.engines.interpolated import best_settings
from render.engines.modes import HeldOutComparison, most_accurate_mode
from render.evaluation import evaluate
from render.guards import relight_warnings
from render.held_out_lights import test_field_from_lp
from render.light_splits import split_lights
from sim.skies import procedural_sky

__all__ = [
    "MODEL_ADVICE",
    "AdviceRecord",
    "AdviceResults",
    "advice_records",
    "format_advice",
    "main",
    "run",
]

#: Warnings whose cure may be the per-sample models.
MODEL_ADVICE = (
    "ghosting",
    "noisy-capture",
    "sun-sparse-lights",
    "sun-ghosting",
    "view-outside",
    "grazing-view",
)


class AdviceRecord(TypedDict):
    """One guard firing on one dataset under one panorama."""

    dataset: str
    family: str
    panorama: str
    warning: str
    comparison: str
    models_win_held_out: bool
    in_use: float
    old_advice: float
    new_advice: float
    in_use_psnr: float
    old_advice_psnr: float
    new_advice_psnr: float
    message: str


class AdviceResults(TypedDict):
    """What :func:`run` writes to ``guard_advice.json``."""

    records: list[AdviceRecord]
    seconds: float


def advice_records(
    dataset: str,
    family: str,
    fit: ReflectanceField,
    test: ReflectanceField,
    panoramas: dict[str, NDArray[np.float32]],
) -> list[AdviceRecord]:
    """The guards that fire on ``fit`` (interpolated), each with its advice scored on ``test``.

    Parameters
    ----------
    dataset, family : labels
    fit : ReflectanceField, the lights the methods and the guards see
    test : ReflectanceField, the same cameras and samples under other lights
    panoramas : name -> ndarray (H, 2H, 3), the lighting the guards are asked about
    """
    models = fit_sample_models(fit)
    comparison: HeldOutComparison = most_accurate_mode(fit, models).comparison
    mode = best_settings(fit)
    scored = evaluate(fit, test, [comparison.interpolation, comparison.model])
    by_name = {m.name: m.mean for m in scored.methods if m.mean is not None}
    interpolated, modelled = by_name[comparison.interpolation], by_name[comparison.model]
    view = fit.cameras[len(fit.cameras) // 2]
    records: list[AdviceRecord] = []
    for name, rgb in panoramas.items():
        for warning in relight_warnings(fit, view, rgb, mode, models, comparison):
            if warning.code not in MODEL_ADVICE:
                continue
            advised = modelled if comparison.models_win else interpolated
            records.append(
                {
                    "dataset": dataset,
                    "family": family,
                    "panorama": name,
                    "warning": warning.code,
                    "comparison": str(comparison),
                    "models_win_held_out": comparison.models_win,
                    "in_use": interpolated.rel_rmse,
                    "old_advice": modelled.rel_rmse,
                    "new_advice": advised.rel_rmse,
                    "in_use_psnr": interpolated.psnr,
                    "old_advice_psnr": modelled.psnr,
                    "new_advice_psnr": advised.psnr,
                    "message": warning.message,
                }
            )
    return records


def _panoramas(quick: bool) -> dict[str, NDArray[np.float32]]:
    height = 64 if quick else 128
    return {
        "sky, 90 % in its sun": procedural_sky(height, sun_share=0.9),
        "courtyard": read_panorama(panorama_path("courtyard")).rgb,
    }


def run(
    out: Path,
    *,
    quick: bool,
    rti_worlds: Sequence[tuple[str, Path, Path]] = (),
    worlds: Sequence[tuple[str, Path, Path]] = (),
    own_family: Sequence[tuple[str, Path, Path]] = (),
) -> AdviceResults:
    """Measure every dataset; write ``out/guard_advice.json`` and ``out/guard_advice.md``.

    Parameters
    ----------
    out : Path
    quick : bool, one split of the real capture
    rti_worlds : (name, fit .lp, test .lp) of path-traced RTI captures
    worlds : (name, fit store, test store) of path-traced fields of points
    own_family : (name, fit store, test store) of the simulator's fields
    """
    start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    panoramas = _panoramas(quick)
    records: list[AdviceRecord] = []
    with open_field_or_rti(rti_capture_path()) as capture:
        for split in ("every-other",) if quick else ("every-other", "rings", "random:0"):
            fit_index, test_index = split_lights(capture, split)
            fit, test = capture.subset(lights=fit_index), capture.subset(lights=test_index)
            records += advice_records(f"RTI lion, {split}", "real", fit, test, panoramas)
    for name, fit_lp, test_lp in rti_worlds:
        with open_field_or_rti(fit_lp) as fit:
            test = test_field_from_lp(test_lp)
            records += advice_records(f"{name} (RTI dome)", "path-traced", fit, test, panoramas)
    for family, items in (("path-traced", worlds), ("own family", own_family)):
        for name, fit_path, test_path in items:
            fit, test = ReflectanceField.open(fit_path), ReflectanceField.open(test_path)
            records += advice_records(name, family, fit, test, panoramas)
    results: AdviceResults = {"records": records, "seconds": time.perf_counter() - start}
    (out / "guard_advice.json").write_text(json.dumps(results, indent=2) + "\n")
    (out / "guard_advice.md").write_text(format_advice(records))
    return results


def _improves(before: float, after: float) -> str:
    if math.isclose(before, after):
        return "same"
    return "better" if after < before else "worse"


def format_advice(records: Sequence[AdviceRecord]) -> str:
    """A Markdown table: each firing, its test-light error in use and under either advice."""
    lines = [
        "Guards whose advice may be the per-sample models, where they fire (interpolating "
        "mode); relative RMSE on test lights no method saw (PSNR on 8-bit sRGB).",
        "",
        "| dataset | family | panorama | warning | in use | old advice (models) | "
        "new advice | held-out comparison on the fit lights |",
        "|---|---|---|---|---:|---:|---:|---|",
    ]
    for r in records:
        new = "models" if r["models_win_held_out"] else "keep, capture more"
        lines.append(
            f"| {r['dataset']} | {r['family']} | {r['panorama']} | {r['warning']} | "
            f"{r['in_use']:.1%} ({r['in_use_psnr']:.1f} dB) | "
            f"{r['old_advice']:.1%} ({r['old_advice_psnr']:.1f} dB), "
            f"{_improves(r['in_use'], r['old_advice'])} | "
            f"{new}: {r['new_advice']:.1%}, {_improves(r['in_use'], r['new_advice'])} | "
            f"{r['comparison']} |"
        )
    old_worse = sum(r["old_advice"] > r["in_use"] for r in records)
    new_worse = sum(r["new_advice"] > r["in_use"] for r in records)
    lines += [
        "",
        f"{len(records)} firings: the old advice made {old_worse} worse, the new advice "
        f"{new_worse}.",
    ]
    return "\n".join(lines) + "\n"


def _spec(text: str) -> tuple[int, int, int, int, int]:
    values = tuple(int(v) for v in text.split(","))
    if len(values) != 5:
        raise argparse.ArgumentTypeError(f"five whole numbers separated by commas, got {text!r}")
    return values


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.guard_advice -o DIR [--quick] [--fields DIR] [--world ...]``.

    The defaults are the data of ``rig bench --quick`` (rendered once, kept in ``--fields``).
    """
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--quick", action="store_true", help="one split of the real capture")
    parser.add_argument("--fields", type=Path, help="where path-traced data are made and kept")
    parser.add_argument("--rti-world", action="append", help="world of an RTI dome (repeat)")
    parser.add_argument("--rti-spec", type=_spec, default=(49, 20, 64, 48, 64),
                        help="fit lights, test lights, width, height, spp")  # fmt: skip
    parser.add_argument("--world", action="append", help="world of a field of points (repeat)")
    parser.add_argument("--world-spec", type=_spec, default=(4, 24, 64, 64, 3000),
                        help="cameras, lights, image side, spp, points")  # fmt: skip
    args = parser.parse_args(argv)
    from bench.held_out import own_family_fields, world_fields, world_rti_captures

    fields_dir = args.fields or args.output / "fields"
    fields_dir.mkdir(parents=True, exist_ok=True)
    rti = world_rti_captures(fields_dir, args.rti_world or ["clearcoat-relief"], args.rti_spec)
    worlds = world_fields(fields_dir, args.world or ["copper-bowl"], args.world_spec)
    own = own_family_fields(fields_dir, quick=args.quick)
    results = run(args.output, quick=args.quick, rti_worlds=rti, worlds=worlds, own_family=own)
    print((args.output / "guard_advice.md").read_text(), end="")
    print(f"{results['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    from core.progress import drawing_bars

    with drawing_bars():  # the library's bars on stderr, as ``rig`` draws them
        status = main()
    raise SystemExit(status)
