"""The simulated world's commands: ``rig sim scenes``, ``render``, ``photo``, ``field``, ``rti``.

Application layer: parses and calls the simulator (:mod:`sim.scenes`, :mod:`sim.ground_truth`,
:mod:`sim.synthetic_camera`, :mod:`sim.field`, :mod:`sim.rti_capture`, and the path-traced
worlds of :mod:`sim.world.mitsuba`); ``rig sim start`` is :mod:`app.cli.rig`'s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli.args import (
    add_camera_options,
    angles,
    count,
    image_size,
    output_directory,
    output_file,
    positive,
    whole,
)
from app.cli.rig import add_sim_start
from core.errors import InputError, RigError


def add_sim(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig sim`` and its sub-commands on the ``rig`` sub-command parser."""
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
            dtype=args.dtype, overwrite=args.overwrite,
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
    make_world_rti(out, str(world.source), spec, max_depth=args.max_depth, image_format=args.format)
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
