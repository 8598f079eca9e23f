"""Does the default choose the rung that predicts the requested lights best? Expected vs actual.

``rig relight FIT.lp --lights TEST.lp`` chooses among the rungs (:mod:`render.rung_choice`)
by the PSNR each is expected to reach on the requested lights, from folds of the capture's
own lights. This study runs that choice on captures that come with other lights to predict,
then predicts those lights with every rung (fitted on every fit light, as the default does)
and scores them (8-bit sRGB PSNR over the capture's mask, the mean squared error of every test
image): per rung, the expected and the actual PSNR side by side; for the default, the rung or
mixture it chose and what that scored, beside ``rbf``, ``ptm-8bit`` and ``hsh3-8bit``.

Captures: RTI folders holding ``fit.lp`` and ``test.lp`` (``rig sim rti --format jpeg``) and
the bundled real capture split ``every-other``. Writes ``choice_study.json`` and
``choice_study.png`` (expected against actual PSNR, one marker per rung and capture).

Run: ``python -m bench.choice_study -o DIR [--capture FOLDER ...] [--fast] [--seconds S]``.
``--seconds`` caps the learned rung's training (the default's own cap otherwise); the figures
of one run compare rungs on one machine's speed.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt
import numpy as np

from core.field_store import ReflectanceField
from core.sample_data import rti_capture_path
from processing.image_quality import psnr_8bit
from processing.learned_rti_training import TrainingSettings
from processing.rti import open_field_or_rti
from render.held_out_lights import test_field_from_lp
from render.light_prediction import make_predictor
from render.light_splits import split_lights
from render.prediction_methods import LightPredictor, MixturePredictor
from render.rung_choice import choose_light_rung

#: Baselines reported beside the default whether or not it chose them.
BASELINES = ("rbf", "ptm-8bit", "hsh3-8bit")


def _actual(fit: ReflectanceField, test: ReflectanceField, predictor: LightPredictor) -> float:
    """PSNR (dB) of ``predictor``'s images of the test lights: every image's MSE, averaged."""
    shape = fit.image_shape
    assert shape is not None
    predicted = predictor.predict(0, test.light_directions)
    truth = test.camera_slab(0)
    seen = (fit.visibility[0] & test.visibility[0]).reshape(shape)
    mse = [
        255.0**2 * 10.0 ** (-psnr_8bit(p.reshape(*shape, 3), t.reshape(*shape, 3), seen) / 10.0)
        for p, t in zip(predicted, truth, strict=True)
    ]
    mean = float(np.mean(mse))
    return math.inf if mean == 0 else 10.0 * math.log10(255.0**2 / mean)


@contextlib.contextmanager
def _pair(capture: Path | None) -> Iterator[tuple[str, ReflectanceField, ReflectanceField]]:
    """(name, fit, test) of an RTI folder (fit.lp, test.lp), or of the bundled real capture."""
    if capture is None:
        with open_field_or_rti(rti_capture_path()) as field:
            fit_index, test_index = split_lights(field, "every-other")
            yield "lion", field.subset(lights=fit_index), field.subset(lights=test_index)
        return
    with open_field_or_rti(capture / "fit.lp") as fit:
        yield capture.name, fit.subset(), test_field_from_lp(capture / "test.lp")


def study(capture: Path | None, *, fast: bool, learned: TrainingSettings) -> dict[str, Any]:
    """One capture: the choice's expected PSNR and every rung's actual one."""
    with _pair(capture) as (name, fit, test):
        start = time.perf_counter()
        choice = choose_light_rung(fit, test.light_directions, fast=fast, learned=learned)
        choosing = time.perf_counter() - start
        rungs: dict[str, dict[str, float]] = {}
        for score in choice.scores:
            if not math.isfinite(score.psnr):
                continue
            # Trained or fitted once: the choice's own fits on every light are reused.
            if score.name == "mixture":
                assert choice.weights is not None
                members = [make_predictor(fit, m, learned=learned) for m in choice.members]
                predictor: LightPredictor = MixturePredictor(fit, members, choice.weights)
            else:
                predictor = make_predictor(fit, score.name, learned=learned)
            rungs[score.name] = {
                "expected": score.psnr,
                "actual": _actual(fit, test, predictor),
                "seconds": score.seconds,
            }
        for baseline in BASELINES:
            if baseline not in rungs:
                actual = _actual(fit, test, make_predictor(fit, baseline))
                rungs[baseline] = {"expected": math.nan, "actual": actual, "seconds": math.nan}
        chosen = rungs[choice.name]["actual"]
        best = max(rungs[b]["actual"] for b in BASELINES)
        print(
            f"{name}: chose {choice.describe()} in {choosing:.0f} s: {chosen:.2f} dB; "
            f"rbf {rungs['rbf']['actual']:.2f}, best of rbf/PTM/HSH {best:.2f}",
            flush=True,
        )
        for rung, row in rungs.items():
            print(f"  {rung:24s} expected {row['expected']:6.2f}  actual {row['actual']:6.2f}")
        return {
            "capture": name,
            "chosen": choice.name,
            "members": list(choice.members),
            "choosing_seconds": choosing,
            "default": chosen,
            "best_baseline": best,
            "rungs": rungs,
        }


def chart(results: list[dict[str, Any]], path: Path) -> None:
    """Expected against actual PSNR, one marker per rung and capture; the chosen ringed."""
    figure, axes = plt.subplots(figsize=(6.5, 5.5))
    names = sorted({rung for r in results for rung in r["rungs"]})
    for i, rung in enumerate(names):
        points = [(r["rungs"][rung], r) for r in results if rung in r["rungs"]]
        xs = [p["expected"] for p, _ in points]
        ys = [p["actual"] for p, _ in points]
        axes.scatter(xs, ys, color=f"C{i % 10}", marker="os^v<>"[i // 10], label=rung, s=22)
        for (_, r), x, y in zip(points, xs, ys, strict=True):
            if r["chosen"] == rung:
                axes.scatter([x], [y], s=120, facecolors="none", edgecolors="black")
    low = min(min(p["actual"], np.nan_to_num(p["expected"], nan=99)) for r in results
              for p in r["rungs"].values())  # fmt: skip
    high = max(p["actual"] for r in results for p in r["rungs"].values())
    axes.plot([low, high], [low, high], color="grey", lw=0.8)
    axes.set_xlabel("expected PSNR from the capture's own lights (dB)")
    axes.set_ylabel("PSNR on the requested lights (dB)")
    axes.set_title("the default's choice: expected against actual (ringed: chosen)")
    axes.legend(fontsize=7, ncol=2)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m bench.choice_study", description=__doc__)
    parser.add_argument("-o", "--output", type=Path, required=True, help="new or empty folder")
    parser.add_argument("--capture", type=Path, action="append", default=[],
                        help="RTI folder with fit.lp and test.lp (repeatable)")  # fmt: skip
    parser.add_argument("--no-lion", action="store_true", help="leave out the bundled capture")
    parser.add_argument("--fast", action="store_true", help="the quick rungs only (--fast)")
    parser.add_argument("--seconds", type=float, help="cap of the learned rung's training")
    args = parser.parse_args(argv)
    learned = TrainingSettings()
    if args.seconds is not None:
        learned = replace(learned, max_seconds=args.seconds)
    args.output.mkdir(parents=True, exist_ok=True)
    captures: list[Path | None] = [*args.capture, *([] if args.no_lion else [None])]
    results = [study(c, fast=args.fast, learned=learned) for c in captures]
    (args.output / "choice_study.json").write_text(json.dumps(results, indent=1))
    chart(results, args.output / "choice_study.png")
    print(f"wrote {args.output / 'choice_study.json'} and choice_study.png")


if __name__ == "__main__":
    main()
