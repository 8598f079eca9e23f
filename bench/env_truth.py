"""Environment relighting of an RTI capture against physics, and against the light-stage sum.

For each scene on a base (``sim/worlds/matte-still-life``, ``plastic-gold``, ``glazed-bowl``)
and each dome (49 and 100 Fibonacci lights above the horizon), an overhead RTI capture is
path-traced (:func:`sim.world.rti.render_world_rti`) and written as the project's RTI import
reads it (16-bit linear TIFF, ``fit.lp`` in the camera frame, ``fit.mask.png``). The same scene
is path-traced under each panorama (:func:`sim.world.mitsuba.render_world_environment`): the
truth. Each method predicts that truth from the capture:

``light-stage sum (full sphere)``
    Debevec et al. 2000: every panorama pixel given to its nearest capture light (a Voronoi
    cell on the whole sphere), radiance x solid angle summed per cell (an irradiance), the
    captured images weighted by it (:func:`light_stage_sum`, written here from scratch);
``light-stage sum (upper hemisphere)``
    the same without the panorama below the horizon (the base hides it from the object);
the product's command line
    ``rig relight CAPTURE/fit.lp --env PANO.exr -o OUT.exr`` plus the flags of
    :data:`CLI_METHODS` (``--fast``: the default choice among the quick rungs), run as a
    subprocess; its output divided by the capture's exposure scale (the 16-bit white's
    radiance). The default proper, whose choice trains a network per run (minutes), runs under
    the panoramas given to ``--slow``.

Scores (:func:`scores`) are relative RMSE ||pred - truth|| / ||truth|| over every pixel of the
view (the base fills it), over the object's pixels and over the base's (told apart by the
height of the surface each pixel shows), and the ratio of mean brightness pred / truth.

Run ``python -m bench.env_truth -o DIR [--quick] [--scenes ...] [--slow PANORAMA ...]``
(scenes may run as separate processes on one DIR, then once more together): renders and the
command's outputs are cached in DIR (a re-run reuses them); DIR/env_truth.json,
DIR/env_truth.md and DIR/env_truth.png are written. What is compared (the methods' labels and
flags), a score's layout and the report (tables, chart) are :mod:`bench.env_truth_report`.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, cast

import numpy as np
from numpy.typing import NDArray

from bench.env_truth_report import (
    CLI_METHODS,
    SLOW_CLI_METHODS,
    SUM_FULL,
    SUM_UPPER,
    Records,
    Score,
    _fmt,
    chart,
    format_tables,
)
from core.camera_model import PinholeCamera, rig_to_camera
from core.directions import hemisphere_layout, panorama_directions, panorama_solid_angles
from core.image_io import read_pixels, write_exr
from core.sample_data import panorama_path
from processing.image_quality import relative_rmse_values
from processing.panorama import downsample_panorama, read_panorama
from sim.rti_capture import write_rti_capture
from sim.skies import procedural_sky
from sim.world.mitsuba import DEFAULT_MAX_DEPTH, load_world, render_world_environment
from sim.world.render import WorldRenderer
from sim.world.rti import overhead_camera, render_world_rti

__all__ = [
    "DOMES",
    "FULL",
    "PANORAMAS",
    "QUICK",
    "RINGS",
    "SCENES",
    "Capture",
    "Settings",
    "capture",
    "dome_directions",
    "light_stage_sum",
    "main",
    "panoramas",
    "relative_rmse",
    "run",
    "run_cli",
    "scores",
    "truth",
]

#: The scenes on a base (world files in sim/worlds/).
SCENES: tuple[str, ...] = ("matte-still-life", "plastic-gold", "glazed-bowl")
#: Domes: 49 and 100 Fibonacci lights over the upper hemisphere (the lowest 0.6 and 0.3
#: degrees above the horizon), and 49 lights in rings from 15 degrees of elevation up, as real
#: domes leave their lowest band unlit (:func:`dome_directions`).
DOMES: tuple[str, ...] = ("49", "100", "49-rings")
#: The ring dome: (elevation in degrees, lights) per ring, and one light at the zenith.
RINGS: tuple[tuple[float, int], ...] = ((15.0, 16), (30.0, 13), (45.0, 10), (60.0, 6), (75.0, 3))
#: The panoramas: two bundled photographs, a procedural sky with a sun carrying 90 % of the
#: light, and a uniform white sky (radiance 1 everywhere).
PANORAMAS: tuple[str, ...] = ("courtyard", "studio", "sun-sky", "white")
#: A pixel shows the base when its surface lies this close to the base's height (scene units).
BASE_TOLERANCE = 0.005
RIG = Path(sys.executable).with_name("rig")


@dataclass(frozen=True)
class Settings:
    """What is rendered: image side (pixels), capture and truth samples per pixel, panorama rows."""

    size: int
    capture_spp: int
    truth_spp: int
    panorama_height: int

    @property
    def tag(self) -> str:
        """Names the cached renders, so runs at other settings do not reuse them."""
        return f"{self.size}px-{self.capture_spp}spp"


#: Square sample counts (the multijitter sampler rounds others up). Truth noise at 1024 spp is
#: 1-3 % under a panorama (docs/world.md); the capture's noise averages over the lights summed.
FULL = Settings(size=128, capture_spp=64, truth_spp=1024, panorama_height=64)
QUICK = Settings(size=64, capture_spp=36, truth_spp=1024, panorama_height=64)


@dataclass(frozen=True)
class Capture:
    """An RTI capture as written, and what scoring needs of its view.

    Attributes
    ----------
    lp : Path, the capture's ``fit.lp``
    images : ndarray, shape (T, H, W, 3), float32, linear radiance under unit irradiance as
        written (16-bit levels over ``scale``)
    directions : ndarray, shape (T, 3), float64, unit vectors toward the lights, rig frame
    scale : float, the radiance written as 16-bit white (relit output / scale = radiance)
    object_mask, base_mask : ndarray, shape (H, W), bool, pixels showing an object or the base
    camera : PinholeCamera, the overhead camera
    seconds : float, wall time of the render (0 when cached before this run's version)
    """

    lp: Path
    images: NDArray[np.float32]
    directions: NDArray[np.float64]
    scale: float
    object_mask: NDArray[np.bool_]
    base_mask: NDArray[np.bool_]
    camera: PinholeCamera
    seconds: float


def panoramas(settings: Settings) -> dict[str, NDArray[np.float32]]:
    """Every panorama of :data:`PANORAMAS` at ``settings.panorama_height`` rows, linear RGB."""
    height = settings.panorama_height
    found: dict[str, NDArray[np.float32]] = {}
    for name in PANORAMAS:
        if name in ("courtyard", "studio"):
            rgb = read_panorama(panorama_path(cast(Literal["courtyard", "studio"], name))).rgb
            found[name] = downsample_panorama(rgb, height)
        elif name == "sun-sky":
            found[name] = procedural_sky(height)
        else:
            found[name] = np.ones((height, 2 * height, 3), dtype=np.float32)
    return found


def light_stage_sum(
    images: NDArray[np.floating],
    directions: NDArray[np.floating],
    panorama: NDArray[np.floating],
    *,
    upper_only: bool = False,
) -> NDArray[np.float64]:
    """Relight a capture by the light-stage sum (Debevec et al. 2000).

    Every panorama pixel goes to its nearest light (largest cosine: the Voronoi cells of the
    lights on the sphere); a light's weight is the sum of radiance x solid angle over its cell,
    the irradiance it stands for; the relit image is the images weighted by it.

    Parameters
    ----------
    images : ndarray, shape (T, H, W, 3), linear radiance of each image per unit irradiance
    directions : ndarray, shape (T, 3), unit vectors toward the lights, the panorama's frame
    panorama : ndarray, shape (h, 2h, 3), linear radiance (``docs/conventions.md``)
    upper_only : bool, drop the panorama's pixels below the horizon (z < 0)

    Returns
    -------
    ndarray, shape (H, W, 3), float64, linear radiance
    """
    light = np.asarray(panorama, dtype=np.float64)
    rows, cols = light.shape[:2]
    towards = panorama_directions(rows, cols).reshape(-1, 3)
    energy = (light * panorama_solid_angles(rows, cols)[:, :, None]).reshape(-1, 3)
    if upper_only:
        energy = energy * (towards[:, 2] >= 0.0)[:, None]
    cell = np.argmax(towards @ np.asarray(directions, dtype=np.float64).T, axis=1)
    weights = np.zeros((len(directions), 3))
    np.add.at(weights, cell, energy)
    return np.einsum("thwc,tc->hwc", np.asarray(images, dtype=np.float64), weights)


def relative_rmse(
    pred: NDArray[np.floating], truth: NDArray[np.floating], mask: NDArray[np.bool_]
) -> float | None:
    """||pred - truth|| / ||truth|| over the masked pixels and all channels.

    :func:`processing.image_quality.relative_rmse_values`, but None (no score) for an empty
    mask or a black truth.

    Parameters
    ----------
    pred, truth : ndarray, shape (H, W, 3), linear radiance
    mask : ndarray, shape (H, W), bool
    """
    if not mask.any() or not np.any(np.asarray(truth)[mask]):
        return None
    return relative_rmse_values(pred, truth, mask)


def _ratio(
    pred: NDArray[np.floating], truth: NDArray[np.floating], mask: NDArray[np.bool_]
) -> float | None:
    if not mask.any():
        return None
    mean = float(np.mean(truth[mask], dtype=np.float64))
    return float(np.mean(pred[mask], dtype=np.float64)) / mean if mean > 0 else None


def scores(
    pred: NDArray[np.floating],
    truth: NDArray[np.floating],
    object_mask: NDArray[np.bool_],
    base_mask: NDArray[np.bool_],
    seconds: float,
) -> Score:
    """Relative RMSE and brightness ratio over the whole view, the object and the base."""
    everything = object_mask | base_mask
    return {
        "rel_rmse": relative_rmse(pred, truth, everything),
        "rel_rmse_object": relative_rmse(pred, truth, object_mask),
        "rel_rmse_base": relative_rmse(pred, truth, base_mask),
        "ratio": _ratio(pred, truth, everything),
        "ratio_object": _ratio(pred, truth, object_mask),
        "ratio_base": _ratio(pred, truth, base_mask),
        "seconds": seconds,
        "error": "",
        "note": "",
    }


def _failed(error: str, seconds: float) -> Score:
    return {"rel_rmse": None, "rel_rmse_object": None, "rel_rmse_base": None, "ratio": None,
            "ratio_object": None, "ratio_base": None, "seconds": seconds,
            "error": error, "note": ""}  # fmt: skip


def dome_directions(dome: str) -> NDArray[np.float64]:
    """Unit vectors (T, 3) toward the lights of a :data:`DOMES` entry, rig frame."""
    if dome.endswith("-rings"):
        rings = [np.array([[0.0, 0.0, 1.0]])]
        for elevation, count in RINGS:
            azimuth = np.radians((np.arange(count) + 0.5 * (count % 2)) * 360.0 / count)
            up = math.radians(elevation)
            rings.append(np.stack([math.cos(up) * np.cos(azimuth), math.cos(up) * np.sin(azimuth),
                                   np.full(count, math.sin(up))], axis=1))  # fmt: skip
        return np.concatenate(rings)
    return hemisphere_layout(int(dome), "fibonacci")


def capture(folder: Path, scene: str, dome: str, settings: Settings) -> Capture:
    """Render (once; cached in ``folder``) an overhead capture of ``scene`` under a dome.

    The exposure puts the brightest value of all images at 16-bit white, so nothing clips and
    the relit radiance is comparable with the truth in absolute terms; the images kept are the
    16-bit levels over that scale, exactly what the import reads.
    """
    cache = folder / "capture.npz"
    camera = overhead_camera(settings.size, settings.size)
    if not cache.exists():
        start = time.perf_counter()
        world = load_world(scene)
        # Each dome its own seeds, so the two captures' noise is independent.
        lights = dome_directions(dome)
        rti = render_world_rti(world, lights, width=settings.size, height=settings.size,
                               spp=settings.capture_spp, seed=len(lights) + len(dome))  # fmt: skip
        renderer = WorldRenderer(world, camera, spp=1, max_depth=DEFAULT_MAX_DEPTH)
        geometry = renderer.geometry()
        base_z = -math.inf if world.base_z is None else world.base_z
        height = geometry.position[:, :, 2]
        object_mask = geometry.hit & (height > base_z + BASE_TOLERANCE)
        base_mask = geometry.hit & ~object_mask
        scale = 1.0 / max(float(rti.images.max()), 1e-12)
        write_rti_capture(folder, "fit", rti.images, rig_to_camera(rti.directions, camera),
                          scale=scale, mask=rti.alpha >= 0.5)  # fmt: skip
        levels = np.round(np.clip(rti.images * scale, 0.0, 1.0) * 65535.0)
        np.savez_compressed(cache, images=(levels / (65535.0 * scale)).astype(np.float32),
                            directions=rti.directions, scale=scale, object_mask=object_mask,
                            base_mask=base_mask, seconds=time.perf_counter() - start)  # fmt: skip
    with np.load(cache) as data:
        return Capture(
            lp=folder / "fit.lp",
            images=data["images"],
            directions=data["directions"],
            scale=float(data["scale"]),
            object_mask=data["object_mask"],
            base_mask=data["base_mask"],
            camera=camera,
            seconds=float(data["seconds"]),
        )


def truth(
    path: Path, scene: str, panorama: NDArray[np.float32], camera: PinholeCamera, spp: int
) -> tuple[NDArray[np.float32], float]:
    """The scene path-traced under the panorama (once; cached at ``path``), and its seconds."""
    if not path.exists():
        start = time.perf_counter()
        rgb, _ = render_world_environment(load_world(scene), panorama, camera, spp=spp, seed=7)
        np.savez_compressed(path, rgb=rgb, seconds=time.perf_counter() - start)
    with np.load(path) as data:
        return data["rgb"], float(data["seconds"])


def run_cli(
    lp: Path, panorama: Path, flags: Sequence[str], output: Path
) -> tuple[NDArray[np.float32] | None, str, float]:
    """``rig relight LP --env PANORAMA -o OUTPUT FLAGS``: its image (or None), a note, seconds.

    The image is the output's RGB as written (the capture's exposure not yet undone). The note
    is the error of a run that failed (its last lines of output), else the mode the command
    says it chose (empty when it says none).
    """
    # The per-sample fit is kept beside the capture, as the command keeps it beside a store:
    # the import is to a temporary store, so without --models every run would fit again.
    models = lp.with_name("fit.models.npz")
    command = [str(RIG), "relight", str(lp), "--env", str(panorama), "-o", str(output),
               "--models", str(models), *flags]  # fmt: skip
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0 or not output.exists():
        said = (done.stderr.strip() or done.stdout.strip()).splitlines()[-3:]
        return None, f"exit {done.returncode}: {' | '.join(said)}", seconds
    pixels = read_pixels(output)
    mode = [line for line in done.stdout.splitlines() if line.startswith("relighting mode:")]
    return np.asarray(pixels, dtype=np.float32)[:, :, :3], " ".join(mode), seconds


def _slug(label: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in label).strip("-")


def _cached_cli(
    lp: Path, panorama: Path, flags: Sequence[str], output: Path
) -> tuple[NDArray[np.float32] | None, str, float]:
    """:func:`run_cli`, or its result kept from an earlier run with the same flags."""
    record = output.with_suffix(".json")
    if record.exists():
        kept = json.loads(record.read_text(encoding="utf-8"))
        if kept["flags"] == list(flags) and (kept["failed"] or output.exists()):
            image = None if kept["failed"] else read_pixels(output)[:, :, :3].astype(np.float32)
            return image, str(kept["note"]), float(kept["seconds"])
    output.parent.mkdir(parents=True, exist_ok=True)
    output.unlink(missing_ok=True)
    image, note, seconds = run_cli(lp, panorama, flags, output)
    record.write_text(json.dumps({"flags": list(flags), "failed": image is None, "note": note,
                                  "seconds": seconds}), encoding="utf-8")  # fmt: skip
    return image, note, seconds


def run(
    out: Path,
    settings: Settings,
    *,
    scenes: Sequence[str] = SCENES,
    methods: Sequence[tuple[str, tuple[str, ...]]] = CLI_METHODS,
    slow: Sequence[str] = (),
) -> Records:
    """Render what is missing, relight by every method, score; returns the records.

    ``slow`` names the panoramas on which :data:`SLOW_CLI_METHODS` run as well.
    """
    out.mkdir(parents=True, exist_ok=True)
    pano_dir = out / "panoramas"
    pano_dir.mkdir(exist_ok=True)
    lights = panoramas(settings)
    pano_files = {}
    for name, rgb in lights.items():
        pano_files[name] = pano_dir / f"{name}-{settings.panorama_height}.exr"
        write_exr(pano_files[name], rgb)
    records: Records = {}
    for scene in scenes:
        records[scene] = {}
        for dome in DOMES:
            folder = out / "captures" / f"{scene}-{dome}-{settings.tag}"
            print(f"{scene}, {dome} lights: capture", flush=True)
            cap = capture(folder, scene, dome, settings)
            cases: dict[str, dict[str, Score]] = {}
            for pano, rgb in lights.items():
                name = f"{scene}-{pano}-{settings.size}px-{settings.truth_spp}spp.npz"
                (out / "truth").mkdir(exist_ok=True)
                print(f"  {pano}: truth", flush=True)
                expected, _ = truth(out / "truth" / name, scene, rgb, cap.camera,
                                    settings.truth_spp)  # fmt: skip
                by_method: dict[str, Score] = {}
                cli = [*methods, *(SLOW_CLI_METHODS if pano in slow else ())]
                for label, upper in ((SUM_FULL, False), (SUM_UPPER, True)):
                    start = time.perf_counter()
                    pred = light_stage_sum(cap.images, cap.directions, rgb, upper_only=upper)
                    by_method[label] = scores(pred, expected, cap.object_mask, cap.base_mask,
                                              time.perf_counter() - start)  # fmt: skip
                for label, flags in cli:
                    target = folder / "relit" / f"{pano}-{_slug(label)}.exr"
                    image, note, seconds = _cached_cli(cap.lp, pano_files[pano], flags, target)
                    if image is None:
                        by_method[label] = _failed(note, seconds)
                    elif image.shape != expected.shape:
                        by_method[label] = _failed(
                            f"output {image.shape} is not the capture's {expected.shape}", seconds
                        )
                    else:
                        by_method[label] = scores(image / cap.scale, expected, cap.object_mask,
                                                  cap.base_mask, seconds)  # fmt: skip
                        by_method[label]["note"] = note
                    print(f"    {label}: {_fmt(by_method[label]['rel_rmse'])} "
                          f"{by_method[label]['error']}", flush=True)  # fmt: skip
                cases[pano] = by_method
            records[scene][str(dome)] = cases
    return records


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m bench.env_truth -o DIR [--quick]``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="folder (renders cached)")
    parser.add_argument("--quick", action="store_true", help="64 x 64, fewer samples per pixel")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    parser.add_argument("--slow", nargs="*", default=[], choices=PANORAMAS, metavar="PANORAMA",
                        help="also run the default proper (trains a network: minutes a run) "
                        "under these panoramas")  # fmt: skip
    args = parser.parse_args(argv)
    settings = QUICK if args.quick else FULL
    start = time.perf_counter()
    records = run(args.output, settings, scenes=args.scenes, slow=args.slow)
    report = {"settings": settings.__dict__, "domes": list(DOMES), "panoramas": list(PANORAMAS),
              "cli_methods": [[label, list(flags)] for label, flags in CLI_METHODS],
              "seconds": time.perf_counter() - start, "records": records}  # fmt: skip
    (args.output / "env_truth.json").write_text(json.dumps(report, indent=1), encoding="utf-8")
    text = format_tables(records)
    (args.output / "env_truth.md").write_text(text, encoding="utf-8")
    chart(records, args.output / "env_truth.png")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
