"""The ``rig`` command line: thin sub-commands over library functions.

This module and :mod:`app.demo` are the application layer: they may import every package
(lazily, so ``rig --help`` stays fast); the library packages keep to the boundaries of
``docs/architecture.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import FrameType

from app.cli_advise import add_advise
from app.cli_args import (
    add_camera_options,
    angles,
    count,
    finite,
    image_size,
    output_directory,
    output_file,
    positive,
    whole,
)
from app.cli_batch import add_batch
from app.cli_bench import add_bench_parser
from app.cli_calibrate import add_calibrate
from app.cli_capture import add_capture
from app.cli_choices import SAMPLERS
from app.cli_evaluate import add_evaluate
from app.cli_export import add_export_web
from app.cli_fit import add_fit
from app.cli_plan import add_plan
from app.cli_process import add_process
from app.cli_relight import add_relight
from app.cli_rig import add_doctor, add_sim_start
from app.cli_view import add_view
from core.errors import InputError, RigError

__all__ = ["build_parser", "main"]


def _add_sample(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
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


def _add_demo(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = commands.add_parser(
        "demo",
        help="run the demonstration pipeline and write its pictures",
        description="Run the demonstration on the bundled panorama and write pictures and a "
        "report to the output directory.",
    )
    p.add_argument("-o", "--output", type=output_directory, default=Path("demo-out"),
                   help="output directory")  # fmt: skip
    p.add_argument("--quick", action="store_true", help="small fields (a smoke test)")
    p.set_defaults(handler=_run_demo)


def _run_demo(args: argparse.Namespace) -> int:
    from app.demo import run_demo

    report = run_demo(args.output, quick=args.quick)
    print(f"demo written to {args.output}/ (see {report})")
    return 0


def _add_sim(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = commands.add_parser("sim", help="the simulated world: scenes, ground truth, fields")
    sim_commands = p.add_subparsers(dest="sim_command", required=True, metavar="SIM_COMMAND")
    scenes = sim_commands.add_parser(
        "scenes",
        help="list the synthetic scenes with their geometry and materials",
        description="List the synthetic scenes with every parameter needed to rebuild them in "
        "another renderer.",
    )
    scenes.add_argument("--json", action="store_true", help="print a JSON list")
    scenes.set_defaults(handler=_run_sim_scenes)
    add_sim_start(sim_commands)

    render = sim_commands.add_parser(
        "render",
        help="render the ground truth of a scene under a panorama",
        description="Render a synthetic scene under a whole environment panorama (direct light, "
        "with shadows) and write linear RGB plus coverage alpha as OpenEXR.",
    )
    render.add_argument("--scene", required=True, help="scene name (see rig sim scenes)")
    render.add_argument("--env", type=Path, required=True, help="panorama file")
    render.add_argument("--view", type=angles, required=True, help="camera AZ,INCL in degrees")
    add_camera_options(render)
    render.add_argument(
        "--points", type=count, default=100_000, help="surface points (default 100k)"
    )
    render.add_argument(
        "--grid",
        type=whole,
        default=32,
        help="pre-filter the panorama into GRID x 2 GRID directions (default 32; error measured "
        "in the docs); 0 = every pixel (exact, slow)",
    )
    _add_renderer_options(render, spp=4096)
    render.add_argument("-o", "--output", type=output_file, required=True, help="output .exr")
    render.set_defaults(handler=_run_sim_render)

    photo = sim_commands.add_parser(
        "photo",
        help="one reflectance-field image: a scene under one light, through a sensor model",
        description="Render a synthetic scene under ONE light (directional of unit irradiance, or "
        "a point light at --light-distance) with shadows. The suffix of -o picks the output: "
        ".exr linear RGB + coverage alpha (no sensor), .png/.jpg 8-bit sRGB, .tif 16-bit linear, "
        ".dng Bayer raw (the last three through the sensor model: exposure, noise, saturation).",
    )
    photo.add_argument("--scene", required=True, help="scene name (see rig sim scenes)")
    photo.add_argument("--view", type=angles, required=True, help="camera AZ,INCL in degrees")
    photo.add_argument("--light", type=angles, required=True, help="light AZ,INCL in degrees")
    photo.add_argument(
        "--light-distance",
        type=positive,
        help="point light at this distance (default: directional)",
    )
    add_camera_options(photo)
    photo.add_argument(
        "--points", type=count, default=250_000, help="surface points (default 250k)"
    )
    photo.add_argument(
        "--exposure-time",
        type=positive,
        help="seconds (default: auto, the brightest 1%% of the object at 80%% of saturation)",
    )
    photo.add_argument("--seed", type=whole, default=0, help="sensor noise seed (default 0)")
    photo.add_argument("--no-noise", action="store_true", help="expected values, no noise")
    photo.add_argument(
        "-o", "--output", type=output_file, required=True, help=".exr/.png/.jpg/.tif/.dng"
    )
    photo.set_defaults(handler=_run_sim_photo)

    field = sim_commands.add_parser(
        "field",
        help="write a reflectance field store straight from the simulator",
        description="Compute the radiance of every surface point under every light from every "
        "camera (directional lights of unit irradiance, shadows included) and the cameras' "
        "visibility masks, and write them as a Zarr field store.",
    )
    field.add_argument("--scene", required=True, help="scene name (see rig sim scenes)")
    field.add_argument("--lights", type=count, required=True, help="number of light directions T")
    field.add_argument("--cameras", type=count, required=True, help="number of cameras S")
    field.add_argument("--layout", choices=("grid", "fibonacci"), default="grid")
    field.add_argument(
        "--points", type=count, default=100_000, help="surface points (default 100k)"
    )
    add_camera_options(field)
    field.add_argument("--dtype", choices=("float32", "float16"), default="float32")
    _add_renderer_options(field, spp=256)
    field.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a field store already at -o (and the fit saved beside it)",
    )
    field.add_argument(
        "-o", "--output", type=output_directory, required=True, help="field store directory"
    )
    field.set_defaults(handler=_run_sim_field)

    rti = sim_commands.add_parser(
        "rti",
        help="an RTI capture of a path-traced world: images, fit.lp and test.lp",
        description="Path-trace a world (sim/worlds or a world .toml) seen from straight above "
        "under a dome of directional lights, as an RTI dome records it: linear 16-bit TIFF "
        "images, fit.lp (the lights to fit, a Fibonacci dome) and test.lp (other lights, a "
        "grid, to predict), with masks of the object (fit.mask.png, test.mask.png); --format jpeg "
        "writes 8-bit sRGB JPEG instead of the TIFFs. Then: "
        "rig evaluate DIR/fit.lp --test DIR/test.lp.",
    )
    rti.add_argument("--scene", required=True, help="world name (sim/worlds) or world .toml")
    rti.add_argument("--lights", type=count, default=49, help="lights to fit (default 49)")
    rti.add_argument("--test-lights", type=count, default=20,
                     help="other lights to predict (default 20)")  # fmt: skip
    rti.add_argument("--size", type=image_size, default=(128, 96), help="WxH (default 128x96)")
    rti.add_argument("--spp", type=count, default=256, help="samples per pixel (default 256)")
    rti.add_argument("--max-depth", type=count, default=8, help="path length (default 8)")
    rti.add_argument("--format", choices=("tiff16", "jpeg"), default="tiff16",
                     help="images: linear 16-bit TIFF (default) or 8-bit sRGB JPEG, as public "
                     "RTI benchmarks ship them")  # fmt: skip
    rti.add_argument("-o", "--output", type=output_directory, required=True, help="new folder")
    rti.set_defaults(handler=_run_sim_rti)


def _add_renderer_options(p: argparse.ArgumentParser, *, spp: int) -> None:
    """``--renderer`` and the path tracer's settings (``sim field`` and ``sim render``)."""
    p.add_argument(
        "--renderer",
        choices=("direct", "mitsuba"),
        default="direct",
        help="direct: the simulator's scenes, direct light (exact for what the models fit); "
        "mitsuba: a path-traced world (--scene names one of sim/worlds or a world .toml; "
        "interreflections, materials outside every fitted model; docs/world.md)",
    )
    p.add_argument(
        "--spp",
        type=count,
        default=spp,
        help=f"mitsuba: samples per pixel (default {spp}; noise in docs/world.md)",
    )
    p.add_argument("--max-depth", type=count, default=8, help="mitsuba: path length (default 8)")


def _run_sim_field(args: argparse.Namespace) -> int:
    from sim.field import field_cameras, simulate_field

    cameras = field_cameras(
        args.cameras,
        args.layout,
        distance=args.distance,
        fov_deg=args.fov,
        width=args.size[0],
        height=args.size[1],
    )
    if args.renderer == "mitsuba":
        from sim.world.mitsuba import load_world, render_world_field

        render_world_field(
            args.output, load_world(args.scene), lights=args.lights, cameras=cameras,
            points=args.points, spp=args.spp, max_depth=args.max_depth, layout=args.layout,
            dtype=args.dtype, progress=True, overwrite=args.overwrite,
        )  # fmt: skip
    else:
        simulate_field(
            args.output,
            args.scene,
            lights=args.lights,
            cameras=cameras,
            points=args.points,
            layout=args.layout,
            dtype=args.dtype,
            progress=True,
            overwrite=args.overwrite,
        )
    print(
        f"{args.scene}: {args.cameras} cameras x {args.lights} lights x {args.points} points "
        f"-> {args.output}"
    )
    return 0


def _run_sim_rti(args: argparse.Namespace) -> int:
    from sim.rti_capture import make_world_rti
    from sim.world.mitsuba import load_world

    out: Path = args.output
    if out.exists() and any(out.iterdir()):
        raise InputError(f"{out}: exists and is not empty; an RTI capture needs a new folder")
    world = load_world(args.scene)  # a bad world is refused before anything renders
    width, height = args.size
    spec = (args.lights, args.test_lights, width, height, args.spp)
    make_world_rti(out, str(world.source), spec, max_depth=args.max_depth,
                   image_format=args.format, progress=True)  # fmt: skip
    print(f"{world.name}: {args.lights} fit + {args.test_lights} test lights, {width}x{height}, "
          f"{args.spp} spp -> {out}/ (rig evaluate {out / 'fit.lp'} --test "
          f"{out / 'test.lp'})")  # fmt: skip
    return 0


def _run_sim_render(args: argparse.Namespace) -> int:
    from core.camera_model import PinholeCamera
    from core.image_io import write_exr
    from processing.panorama import read_panorama
    from sim.ground_truth import render_environment
    from sim.scenes import build_scene, get_scene

    if not args.output.suffix.lower() == ".exr":
        raise RigError(f"{args.output}: the ground truth is written as OpenEXR (.exr)")
    if args.renderer == "mitsuba":
        from sim.world.mitsuba import load_world

        world = load_world(args.scene)  # a bad world file is refused before the panorama
    else:
        spec = get_scene(args.scene)
    panorama = read_panorama(args.env)
    if panorama.note:
        print(panorama.note)
    camera = PinholeCamera(
        args.view[0], args.view[1], args.distance, args.fov, args.size[0], args.size[1]
    )
    if args.renderer == "mitsuba":
        from sim.world.mitsuba import render_world_environment

        rgb, alpha = render_world_environment(
            world, panorama.rgb, camera, spp=args.spp, max_depth=args.max_depth
        )
        write_exr(args.output, rgb, alpha)
        print(f"{world.name} (path-traced, {args.spp} spp) under {panorama.source} -> "
              f"{args.output}")  # fmt: skip
        return 0
    samples = build_scene(spec.name, args.points)
    image = render_environment(
        samples,
        panorama.rgb,
        camera,
        grid_height=args.grid or None,
        shadows=not spec.convex,
        progress=True,
    )
    write_exr(args.output, image.rgb, image.coverage.astype("float32"))
    print(f"{spec.name} under {panorama.source} from {args.view} -> {args.output}")
    return 0


def _run_sim_photo(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from core.camera_model import PinholeCamera
    from core.directions import direction_from_angles_deg
    from core.image_io import write_exr
    from sim.scenes import build_scene, get_scene
    from sim.sensor import Sensor, auto_exposure_time
    from sim.sensor_files import PHOTO_SUFFIXES, write_photo
    from sim.synthetic_camera import DirectionalLight, PointLight, render_under_light

    suffix = args.output.suffix.lower()
    if suffix != ".exr" and suffix not in PHOTO_SUFFIXES:
        raise RigError(f"{args.output}: write .exr or one of {', '.join(PHOTO_SUFFIXES)}")
    spec = get_scene(args.scene)
    camera = PinholeCamera(
        args.view[0], args.view[1], args.distance, args.fov, args.size[0], args.size[1]
    )
    towards = direction_from_angles_deg(*args.light)
    light: DirectionalLight | PointLight
    if args.light_distance is None:
        light = DirectionalLight((float(towards[0]), float(towards[1]), float(towards[2])))
    else:
        where = towards * args.light_distance
        light = PointLight((float(where[0]), float(where[1]), float(where[2])))
    image = render_under_light(build_scene(spec.name, args.points), camera, light)
    if suffix == ".exr":
        write_exr(args.output, image.rgb, image.coverage.astype("float32"))
        print(f"{spec.name} lit from {args.light} seen from {args.view} -> {args.output}")
        return 0
    sensor = Sensor(noise=not args.no_noise)
    seconds = args.exposure_time or auto_exposure_time(image.rgb, sensor, image.coverage > 0)
    write_photo(args.output, image.rgb, replace(sensor, exposure_s=seconds), seed=args.seed)
    print(
        f"{spec.name} lit from {args.light} seen from {args.view}, {seconds * 1e3:.3g} ms "
        f"({PHOTO_SUFFIXES[suffix]}) -> {args.output}"
    )
    return 0


def _run_sim_scenes(args: argparse.Namespace) -> int:
    import json

    from sim.scenes import SCENES

    described = [spec.to_json() for spec in SCENES.values()]
    if args.json:
        print(json.dumps(described, indent=2))
        return 0
    for scene in described:
        material = scene["material"]
        geometry = ", ".join(f"{k}={v}" for k, v in scene["geometry"].items())
        print(f"{scene['name']}: {scene['description']}")
        print(f"  geometry: {geometry}")
        print(
            f"  material: rho_d={material['rho_d']} f0={material['f0']} alpha={material['alpha']}"
        )
        if "texture" in material:
            print(f"  texture:  {material['texture']}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``rig`` argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="rig",
        description="Reflectance-field capture rig and controllable image-based relighting.",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_sample(commands)
    _add_demo(commands)
    add_relight(commands)
    add_view(commands)
    add_export_web(commands)
    add_doctor(commands)
    add_plan(commands)
    add_advise(commands)
    add_evaluate(commands)
    add_fit(commands)
    add_batch(commands)
    add_bench_parser(commands)
    add_capture(commands)
    add_calibrate(commands)
    add_process(commands)
    _add_sim(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rig`` console script; returns the exit status.

    A bad argument is refused by argparse (its message, status 2) and returned as the
    status, like every other refusal, rather than leaving by ``SystemExit``. Ctrl-C and
    SIGTERM both unwind the command (see :func:`_unwind_on_sigterm`): what it created is
    removed, a line on stderr says it was stopped, and the status is the shell's convention,
    128 + the signal's number (130, 143), unless the command handles the stop itself (``rig
    view``, ``rig capture``) and returns its own.
    """
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as leaving:  # argparse's error (2) and --help (0)
        return leaving.code if isinstance(leaving.code, int) else 2
    with _unwind_on_sigterm() as received:
        try:
            status: int = args.handler(args)
        except RigError as error:
            print(f"rig {args.command}: error: {error}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            number = received[-1] if received else signal.SIGINT
            word = "terminated" if number == signal.SIGTERM else "interrupted"
            print(f"rig {args.command}: {word}", file=sys.stderr)
            return 128 + number
    return status


@contextlib.contextmanager
def _unwind_on_sigterm() -> Iterator[list[int]]:
    """SIGTERM raises :class:`KeyboardInterrupt` in the main thread while the block runs.

    By default SIGTERM ends the process where it stands: no ``finally`` or ``with`` runs, so
    a temporary field store (an RTI capture's import), the viewer's uploads or a half-written
    output would stay behind. Raised as Ctrl-C is, it unwinds through the same cleanups and
    the same ``except KeyboardInterrupt`` of the commands that catch it. Yields the list the
    signals received are appended to, so the caller can tell SIGTERM from Ctrl-C. Another
    SIGTERM during that unwinding is ignored: a supervisor repeating its request must not cut
    the cleanup short (SIGKILL is the way to not wait).
    """
    received: list[int] = []

    def terminate(number: int, frame: FrameType | None) -> None:
        received.append(number)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        # A signal handler can only be set from the main thread (a test calling main()
        # from a worker): SIGTERM keeps its default there.
        yield received
        return
    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield received
    finally:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
