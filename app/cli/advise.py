"""``rig advise``: the cheapest relighting of a field within an error tolerance.

Application layer (like the rest of :mod:`app.cli`); the predictions are :mod:`render.advisor`'s.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli.args import count, output_file, positive

if TYPE_CHECKING:
    from render.advisor import Advice

__all__ = ["add_advise", "advice_json", "run_advisor"]


def add_advise(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig advise`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "advise",
        help="the cheapest relighting configuration within an error tolerance",
        description="Predict the error of each relighting configuration (the paper's, our "
        "sampled and every-pixel schemes, per-sample models under sampled or grid lighting) on "
        "a field under an environment, by holding out measured lights and cameras, and print "
        "the fastest one predicted within the tolerance (docs/advisor.md).",
    )
    p.add_argument("field", type=Path, help="reflectance-field store")
    p.add_argument("--env", type=Path, required=True, help="panorama (EXR, .hdr, PNG/JPEG)")
    add_advisor_options(p)
    p.add_argument("--json", type=output_file, help="also write every prediction here")
    p.set_defaults(handler=_run_advise)


def add_advisor_options(p: argparse.ArgumentParser) -> None:
    """The options ``rig advise`` and ``rig plan --advise`` share."""
    p.add_argument(
        "--tolerance", type=positive, default=0.02, help="relative RMSE allowed (default 0.02)"
    )
    p.add_argument(
        "--samples", type=count, default=3000, help="samples to predict on (default 3000)"
    )


def run_advisor(
    field_path: Path, env: Path, tolerance: float, samples: int
) -> tuple[Advice, tuple[int, int]]:
    """Open the field and the panorama, and advise.

    Also returns the field's camera and light counts.
    """
    from core.field_store import ReflectanceField
    from core.light_set import check_measured_lights
    from processing.panorama import read_panorama
    from render.advisor import Advisor

    field = ReflectanceField.open(field_path)
    # Refused before the hold-out fits, as every other opener of a store refuses it: they
    # failed inside a fold, naming a subset or no file ("measured directions 0 and 1 coincide").
    check_measured_lights(
        field_path, field.light_directions, blocked_below=field.below_horizon == "blocked"
    )
    panorama = read_panorama(env)
    if panorama.note:
        print(panorama.note)
    s, t, p = field.shape
    print(f"{field_path}: {s} cameras x {t} lights x {p} samples; environment {env}")
    advice = Advisor(field, samples=samples).advise(panorama, tolerance)
    return advice, (s, t)


def advice_json(advice: Advice) -> dict[str, Any]:
    """Every prediction as plain JSON."""

    def row(prediction: Any) -> dict[str, Any]:
        values = asdict(prediction)
        values["candidate"] = {
            "name": prediction.candidate.name,
            "mode": type(prediction.candidate.mode).__name__,
            "settings": asdict(prediction.candidate.mode),
        }
        return values

    return {
        "tolerance": advice.tolerance,
        "samples": advice.samples,
        "field_samples": advice.field_samples,
        "choice": None if advice.choice is None else advice.choice.candidate.name,
        "predictions": [row(p) for p in advice.predictions],
    }


def _run_advise(args: argparse.Namespace) -> int:
    advice, _ = run_advisor(args.field, args.env, args.tolerance, args.samples)
    print(advice.format())
    if args.json is not None:
        from core.atomic import write_json_atomic

        write_json_atomic(args.json, advice_json(advice))  # checked: a full disk is an error
        print(f"predictions -> {args.json}")
    return 0 if advice.choice is not None else 1
