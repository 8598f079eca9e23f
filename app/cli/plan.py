"""``rig plan``: the dry run of a sweep plan on a rig config (counts, duration, limits).

Application layer (like the rest of :mod:`app.cli`): it reads a plan of :mod:`capture.plan`
and moves nothing.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from capture.plan import SweepPlan
    from rig.config import RigConfig

__all__ = ["add_plan", "format_duration", "plan_report"]


def add_plan(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig plan`` on the ``rig`` sub-command parser."""
    # Spelled out call by call, like every command's parser (duplicates pairs them by shape):
    # the options read here as --help prints them; those shared are app.cli.args' add_*.
    p = commands.add_parser(
        "plan",
        help="dry-run a sweep plan: counts, estimated duration, limit checks",
        description="Read a sweep plan (TOML, see docs/plans.md) and a rig config, and print the "
        "image counts, the pairs the plan skips and why, the estimated duration (motion + "
        "exposure + per-image overhead), the gain of the optimised ordering over the serpentine "
        "one, and each axis' range against its limits. Moves nothing. Exits 0 when the plan "
        "can run, 2 when a camera or light pose lies outside the limits.",
    )
    from app.cli.advise import add_advisor_options

    p.add_argument("--config", type=Path, help="rig config (TOML)")
    p.add_argument("--plan", type=Path, help="sweep plan (TOML); not with --advise")
    p.add_argument(
        "--advise",
        type=Path,
        metavar="PRECAPTURE",
        help="suggest a capture density from the field of a quick sparse pre-capture of the "
        "object (needs --env; with --config, the suggested plan is dry-run on that rig)",
    )
    p.add_argument("--env", type=Path, help="panorama the object will be relit in (--advise)")
    p.add_argument(
        "--all",
        action="store_true",
        help=f"list every skipped pair (default: the first {LISTED_SKIPS} and a count)",
    )
    add_advisor_options(p)
    p.set_defaults(handler=_run_plan)


def format_duration(seconds: float) -> str:
    """``1 h 02 min 03 s``, ``4 min 05 s`` or ``12.3 s``."""
    if not math.isfinite(seconds):
        return "beyond any bound"
    if seconds < 60.0:
        return f"{seconds:.1f} s"
    whole = round(seconds)
    hours, rest = divmod(whole, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours} h {minutes:02d} min {secs:02d} s"
    return f"{minutes} min {secs:02d} s"


#: Skipped pairs listed by default; the rest are counted (``--all`` lists them).
LISTED_SKIPS = 12


def plan_report(
    plan: SweepPlan, config: RigConfig, *, every_skip: bool = False
) -> tuple[list[str], bool]:
    """The report's lines, and whether the plan can run on the rig.

    ``every_skip`` lists every skipped pair; else the first :data:`LISTED_SKIPS` and a count
    of the others, by reason.
    """
    from capture.plan import IMAGE_OVERHEAD_S

    estimate = plan.estimate(config)
    exposures = ", ".join(f"{ms:g}" for ms in plan.exposures_ms)
    images = ", ".join(f"{kind} {count}" for kind, count in estimate.images.items())
    lines = [
        f"cameras: {estimate.cameras}   lights: {estimate.lights}   "
        f"exposures: {estimate.exposures} ({exposures} ms)   "
        f"dark frames: {'yes' if plan.dark_frames else 'no'}",
        f"images: {estimate.total_images} ({images})",
    ]
    skipped = plan.skipped(config)
    lines.append(f"skipped pairs: {len(skipped)}")
    shown = skipped if every_skip else skipped[:LISTED_SKIPS]
    lines += [f"  camera {c}, light {t}: {reason}" for c, t, reason in shown]
    if len(shown) < len(skipped):
        lines.append(f"  ... and {len(skipped) - len(shown)} more (--all lists every one)")
    others = [u for u in plan.unplaced(config) if u.kind != "light"]
    if others:
        lines.append(f"other captures left out: {len(others)}")
        for u in others:
            if u.kind == "calibration" and u.light_index is not None:
                capture = plan.calibration[u.light_index]
                what = f"calibration[{u.light_index}] ({capture.name}) camera {u.camera_index}"
                if capture.light_index is not None:
                    what += f", light {capture.light_index}"
            else:
                what = f"{u.kind} frames of camera {u.camera_index}"
            lines.append(f"  {what}: {u.reason}")
    settle = config.light.settle_s
    lines += [
        f"estimated duration: {format_duration(estimate.total_s)} = motion "
        f"{estimate.motion_s:.1f} s + exposure {estimate.exposure_s:.1f} s + overhead "
        f"{estimate.overhead_s:.1f} s ({IMAGE_OVERHEAD_S:g} s per image"
        + (f", {settle:g} s light settle per switch)" if settle else ")"),
        f"ordering: {plan.ordering}; motion optimised "
        f"{estimate.motion_by_ordering_s['optimised']:.1f} s vs serpentine "
        f"{estimate.motion_by_ordering_s['serpentine']:.1f} s: "
        + (
            f"the optimised order saves {estimate.gain_s:.1f} s ({estimate.gain_fraction:.0%} "
            f"of the serpentine duration, {format_duration(estimate.duration_s('serpentine'))})"
            if estimate.gain_s >= 0
            else "the optimised order moves longer but reaches captures the serpentine one "
            "leaves out"
        ),
        "limits:",
    ]
    checks = plan.limit_checks(config)
    width = max(len(check.role) for check in checks)
    for check in checks:
        verdict = "OK" if check.ok else "VIOLATION"
        lines.append(
            f"  {check.role:<{width}}  plan {check.low_deg:g} .. {check.high_deg:g} deg   "
            f"limits {check.min_deg:g} .. {check.max_deg:g} deg   {verdict}"
        )
    runnable = all(check.ok for check in checks)
    if not runnable:
        lines.append("the plan is not runnable: a camera or light pose lies outside the limits")
    elif estimate.total_images == 0:
        runnable = False
        lines.append("the plan is not runnable: it takes no image on this rig")
    else:
        lines.append("the plan is runnable (nothing was moved)")
    return lines, runnable


def _run_plan(args: argparse.Namespace) -> int:
    from capture.plan_file import load_plan
    from core.errors import InputError
    from rig.config import load_config

    if args.advise is not None:
        return _advise_density(args)
    if args.config is None or args.plan is None:
        raise InputError("rig plan needs --config and --plan (or --advise PRECAPTURE --env P)")
    config = load_config(args.config)
    plan = load_plan(args.plan)
    print(f"plan {args.plan} on {config.name!r} ({args.config})")
    lines, runnable = plan_report(plan, config, every_skip=args.all)
    print("\n".join(lines))
    return 0 if runnable else 2


def _advise_density(args: argparse.Namespace) -> int:
    """``rig plan --advise``: the density a pre-capture suggests, dry-run on a rig if given."""
    from app.cli.advise import run_advisor
    from capture.grid_plan import grid_plan
    from core.errors import InputError
    from render.advisor import capture_density
    from rig.config import load_config

    if args.env is None:
        raise InputError("rig plan --advise needs --env PANORAMA (the lighting to relight in)")
    if args.plan is not None:
        raise InputError("rig plan --advise suggests a plan; leave out --plan")
    advice, (cameras, lights) = run_advisor(args.advise, args.env, args.tolerance, args.samples)
    print(advice.format())
    density = capture_density(advice, cameras, lights)
    print(
        f"suggested capture: {density.cameras} cameras x {density.lights} lights "
        f"({density.cameras * density.lights} images per exposure) for {density.candidate.name}"
    )
    print(f"  because {density.reason}")
    print(
        '  plan (TOML):\n    [cameras]\n    layout = "grid"\n    count = '
        f'{density.cameras}\n    [lights]\n    layout = "grid"\n    count = '
        f"{density.lights}"
    )
    if args.config is not None:
        config = load_config(args.config)
        plan = grid_plan(density.cameras, density.lights, layout="grid")
        lines, runnable = plan_report(plan, config)
        print(f"on {config.name!r} ({args.config}):")
        print("\n".join(lines))
        return 0 if runnable else 2
    return 0
