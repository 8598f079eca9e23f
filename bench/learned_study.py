"""Held-out PSNR of the learned relighting model against its training time, per configuration.

Each configuration of :class:`processing.learned_rti_training.TrainingSettings` is trained on
the fit lights of each capture and scored on its held-out lights (8-bit sRGB PSNR of the test
images' mean squared error, as ``rig evaluate`` scores), beside ``rbf`` in the same run: this
machine's speed varies, so compare the differences within one run.

Captures: RTI ``.lp`` folders holding ``fit.lp`` and ``test.lp`` (``rig sim rti``; convert
them to 8-bit sRGB JPEG as public benchmarks are), and the bundled real capture split
``every-other``. Writes ``learned_study.json`` (per capture: rbf, then per configuration its
PSNR, learned+residual's, seconds, passes and the per-pass curve) and ``learned_study.png``.

Run: ``python -m bench.learned_study -o DIR [--capture FOLDER ...] [--configs a,b]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt
import numpy as np

from core.errors import InputError
from core.field_store import ReflectanceField
from core.sample_data import rti_capture_path
from processing.image_quality import psnr_8bit
from processing.learned_rti_training import TrainingSettings
from processing.rti import open_field_or_rti
from render.held_out_lights import test_field_from_lp
from render.light_prediction import make_predictor
from render.light_splits import split_lights

#: The former rung's network: an encoder, codes of 9, the raw light direction, 50-unit decoder.
_NEURAL_RTI = TrainingSettings(
    encoder=True, rate=5e-3, code_size=9, light_frequencies=0, decoder_width=50
)

#: The configurations compared (name: settings), each a step from the former default to the
#: new one. ``former``: 2,000 steps of 256 samples x 32 lights (about 13 passes).
CONFIGS: dict[str, TrainingSettings] = {
    "former": replace(_NEURAL_RTI, steps=2000, epochs=10_000, lights_per_step=32),
    "all-lights": _NEURAL_RTI,
    "encoder+fourier": replace(_NEURAL_RTI, light_frequencies=2, code_size=16, decoder_width=64),
    "default": TrainingSettings(),
    "default+early-stop": TrainingSettings(validation=0.15),
}


def _psnr(
    fit: ReflectanceField, test: ReflectanceField, name: str, settings: TrainingSettings
) -> tuple[float, float]:
    """(held-out PSNR dB, seconds) of one method: every camera's test images predicted."""
    start = time.perf_counter()
    predictor = make_predictor(fit, name, learned=settings)
    mse = []
    for s in range(test.shape[0]):
        predicted = predictor.predict(s, test.light_directions)
        truth = test.camera_slab(s)
        seen = fit.visibility[s] & test.visibility[s]
        shape = fit.image_shape
        if shape is None:
            raise InputError(f"{fit.path}: the study scores fields of pixels (RTI captures)")
        for q in range(test.shape[1]):
            p = psnr_8bit(
                predicted[q].reshape(*shape, 3), truth[q].reshape(*shape, 3), seen.reshape(shape)
            )
            mse.append(255.0**2 * 10.0 ** (-p / 10.0))
    mean = float(np.mean(mse))
    psnr = math.inf if mean == 0 else 20 * math.log10(255.0) - 10 * math.log10(mean)
    return psnr, time.perf_counter() - start


@contextlib.contextmanager
def _pair(capture: Path | None) -> Iterator[tuple[str, ReflectanceField, ReflectanceField]]:
    """(name, fit, test) of an RTI folder (fit.lp, test.lp), or of the bundled real capture."""
    if capture is None:
        with open_field_or_rti(rti_capture_path()) as field:
            fit_index, test_index = split_lights(field, "every-other")
            yield "loewenkopf", field.subset(lights=fit_index), field.subset(lights=test_index)
        return
    with open_field_or_rti(capture / "fit.lp") as fit:
        yield capture.name, fit.subset(), test_field_from_lp(capture / "test.lp")


def run_study(
    captures: Sequence[Path | None], configs: dict[str, TrainingSettings]
) -> list[dict[str, Any]]:
    """Every configuration on every capture (None: the bundled real capture)."""
    results = []
    for capture in captures:
        with _pair(capture) as (name, fit, test):
            rbf, rbf_seconds = _psnr(fit, test, "rbf", TrainingSettings())
            row: dict[str, Any] = {"capture": name, "rbf": rbf, "rbf_seconds": rbf_seconds}
            for label, settings in configs.items():
                learned, seconds = _psnr(fit, test, "learned", settings)
                residual, _ = _psnr(fit, test, "learned+residual", settings)  # trained once
                model = make_predictor(fit, "learned", learned=settings).model(0)  # type: ignore[attr-defined]
                row[label] = {
                    "psnr": learned,
                    "residual_psnr": residual,
                    "seconds": model.seconds,
                    "predict_seconds": seconds - model.seconds,
                    "steps": model.steps,
                    "epochs": model.epochs,
                    "settings": asdict(settings),
                    "history": [asdict(r) for r in model.history],
                }
                print(
                    f"{name:20s} {label:12s} learned {learned:6.2f}  +residual {residual:6.2f}"
                    f"  rbf {rbf:6.2f}  train {model.seconds:6.1f} s  {model.epochs} passes",
                    flush=True,
                )
            results.append(row)
    return results


def chart(results: list[dict[str, Any]], path: Path, configs: Sequence[str]) -> None:
    """Held-out PSNR above rbf (dB) against training seconds, one marker per capture."""
    figure, axes = plt.subplots(figsize=(7, 4.5))
    for i, label in enumerate(configs):
        xs = [r[label]["seconds"] for r in results]
        ys = [r[label]["psnr"] - r["rbf"] for r in results]
        axes.scatter(xs, ys, color=f"C{i}", label=label)
        for x, y, r in zip(xs, ys, results, strict=True):
            axes.annotate(r["capture"], (x, y), fontsize=6, alpha=0.7)
    axes.axhline(0.0, color="grey", lw=0.8)
    axes.axhline(3.0, color="grey", lw=0.8, ls="--")
    axes.set_xlabel("training time (s)")
    axes.set_ylabel("held-out PSNR - rbf (dB)")
    axes.set_title("learned relighting: held-out lights")
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv: Sequence[str] | None = None) -> None:
    """The command line (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m bench.learned_study", description=__doc__)
    parser.add_argument("-o", "--output", type=Path, required=True, help="new or empty folder")
    parser.add_argument(
        "--capture",
        type=Path,
        action="append",
        default=[],
        help="RTI folder with fit.lp and test.lp (repeatable); the bundled capture always runs",
    )
    parser.add_argument("--configs", default=",".join(CONFIGS), help="of: " + ",".join(CONFIGS))
    parser.add_argument("--seconds", type=float, help="training cap of every configuration")
    args = parser.parse_args(argv)
    names = [c for c in args.configs.split(",") if c]
    unknown = [c for c in names if c not in CONFIGS]
    if unknown:
        raise InputError(f"unknown configurations {unknown}; use some of {', '.join(CONFIGS)}")
    configs = {c: CONFIGS[c] for c in names}
    if args.seconds is not None:
        configs = {c: replace(s, max_seconds=args.seconds) for c, s in configs.items()}
    args.output.mkdir(parents=True, exist_ok=True)
    results = run_study([*args.capture, None], configs)
    (args.output / "learned_study.json").write_text(json.dumps(results, indent=1))
    chart(results, args.output / "learned_study.png", names)
    print(f"wrote {args.output / 'learned_study.json'} and learned_study.png")


if __name__ == "__main__":
    main()
