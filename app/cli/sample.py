"""``rig sample``: importance-sample a panorama into K lights and write their pictures.

Application layer: parses the lighting controls and calls
:func:`render.lighting_outputs.write_lighting_outputs`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli.args import count, finite, output_directory, positive, whole
from app.cli.choices import SAMPLERS


def add_sample(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig sample`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "sample",
        help="importance-sample a panorama and disassemble its light into K lights",
        description="Sample an equirectangular panorama into K light directions, gather all its "
        "light into their spherical Voronoi cells, and write lights.json, overlay.png and "
        "lights.png to the output directory.",
    )
    p.add_argument("panorama", type=Path, help="panorama file (.exr, .hdr, .png, .jpg)")
    p.add_argument("-k", type=count, default=64, help="number of lights (default 64)")
    p.add_argument("--method", choices=SAMPLERS, default="tmed", help="sampler (default tmed)")
    p.add_argument("--seed", type=whole, default=0, help="random seed (default 0)")
    p.add_argument(
        "--exact",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="return exactly K samples (default on)",
    )
    p.add_argument(
        "--paper", action="store_true", help="diffuse plain pixel luminance, as the paper"
    )
    p.add_argument("--modulation", type=Path, help="image multiplying the sampling density")
    p.add_argument("--yaw", type=finite, default=0.0, help="rotate the environment, degrees CCW")
    p.add_argument("--exposure", type=positive, default=1.0, help="radiance scale (default 1)")
    p.add_argument("--resample", action="store_true", help="resize a panorama that is not 2:1")
    p.add_argument("-o", "--output", type=output_directory, required=True, help="output directory")
    p.set_defaults(handler=_run_sample)


def _run_sample(args: argparse.Namespace) -> int:
    from processing.environment import LightingControls, read_modulation_map
    from processing.panorama import read_panorama
    from render.lighting_outputs import write_lighting_outputs

    panorama = read_panorama(args.panorama, resample=args.resample)
    if panorama.note:
        print(panorama.note)
    controls = LightingControls(
        k=args.k,
        method=args.method,
        seed=args.seed,
        exact=args.exact,
        paper=args.paper,
        modulation=None if args.modulation is None else read_modulation_map(args.modulation),
        yaw_deg=args.yaw,
        exposure=args.exposure,
    )
    lighting = write_lighting_outputs(panorama, controls, args.output, progress=True)
    lights = lighting.light_set()
    print(
        f"{lights.k} lights ({controls.method}) from {panorama.source} "
        f"({panorama.width}x{panorama.height}); total light "
        f"{lights.rgb.sum(axis=0).round(4).tolist()} (RGB radiance x sr) -> {args.output}/"
    )
    return 0
