"""``rig advise`` on a world no model contains: predicted error against a path-traced truth.

The advisor (:mod:`render.advisor`) predicts each configuration's error from the field alone.
:mod:`bench.advisor` checks it against the simulator, whose material is the models' own; here
the field is path-traced by Mitsuba 3 (:mod:`sim.world.mitsuba`: interreflections, coloured
Fresnel, clear coats), and so is the truth: the world under the panorama, seen by a captured
camera and by a view halfway between two cameras, each sample's radiance read from the image as
the field's own slabs are (:func:`sim.world.visibility.sample_view`). Every candidate relights
the field at both views and is scored per sample (relative RMSE over the samples both show),
the quantity the advisor predicts.

``python -m bench.advisor_world -o DIR --field STORE [--env NAME ...] [--spp N]`` writes
``advisor_world.json`` and ``advisor_world.md`` (the table of :func:`bench.advisor.format_advisor`
and how often the prediction is within 1.5x of the truth).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, get_args

import numpy as np
from numpy.typing import NDArray

from bench.advisor import TOLERANCE, format_advisor, validate_advisor
from bench.sim_truth import between_view
from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField
from core.sample_data import PanoramaName, panorama_path
from processing.image_quality import relative_rmse_values
from processing.panorama import Panorama, downsample_panorama, panorama_from_array, read_panorama
from processing.sample_model_store import models_for_field
from processing.sample_models import PARAMETRIC_MODELS
from render.engines.interpolated import RelitImage
from sim.field import field_cameras
from sim.world.files import WORLDS, World, load_world
from sim.world.mitsuba import render_world_field
from sim.world.render import WorldRenderer, render_environment_image
from sim.world.samples import world_samples
from sim.world.visibility import sample_view

__all__ = [
    "PANORAMA_HEIGHT",
    "RATIO",
    "main",
    "ratio_summary",
    "real_panoramas",
    "validate_world_advisor",
    "world_field",
]

#: Rows of the panorama both the truth and the relighting see (Mitsuba holds 4x4 texels each).
PANORAMA_HEIGHT = 64
#: The issue's goal: the prediction within this factor of the measured error.
RATIO = 1.5


def _world_of(field: ReflectanceField) -> tuple[World, int, int]:
    """The world a path-traced field was rendered from, its sample seed and max depth."""
    provenance = field.provenance
    if provenance.get("source") != "mitsuba":
        raise InputError(f"{field.path}: not a path-traced world field (rig sim field "
                         "--renderer mitsuba)")  # fmt: skip
    recorded = provenance["world"]
    world = load_world(recorded["name"] if recorded["name"] in WORLDS else recorded["file"])
    if world.digest != recorded["digest"]:
        raise InputError(f"{field.path}: its world ({recorded['file']}) has changed since")
    return world, int(provenance.get("seed", 0)), int(provenance["renderer"]["max_depth"])


def world_truths(
    field: ReflectanceField,
    panoramas: Mapping[str, Panorama],
    views: Mapping[str, PinholeCamera],
    *,
    spp: int,
) -> dict[tuple[str, str], tuple[NDArray[np.float32], NDArray[np.bool_]]]:
    """Path-traced radiance (P, 3) of every sample and whether it is seen, per (env, view)."""
    world, seed, max_depth = _world_of(field)
    samples = world_samples(world, field.shape[2], seed)
    if field.points is None or not np.allclose(samples.points, field.points, atol=1e-5):
        raise InputError(f"{field.path}: its points are not the world's samples (seed {seed})")
    truths = {}
    for view_name, camera in views.items():
        geometry = WorldRenderer(world, camera, spp=1, max_depth=2).geometry()
        view = sample_view(samples, camera, geometry)
        for env, panorama in panoramas.items():
            image = render_environment_image(world, panorama.rgb, camera, spp=spp,
                                             max_depth=max_depth)  # fmt: skip
            truths[(env, view_name)] = (view.radiance(image), view.visible)
    return truths


def validate_world_advisor(
    name: str,
    field: ReflectanceField,
    panoramas: Mapping[str, Panorama],
    *,
    samples: int = 3000,
    spp: int = 256,
    tolerance: float = TOLERANCE,
) -> list[dict[str, Any]]:
    """Predicted and path-traced error of every advisor candidate, per environment.

    Returns
    -------
    list of dict, one per environment and candidate, as :func:`bench.advisor.validate_advisor`
    """
    index = len(field.cameras) // 2
    views = {"captured": field.cameras[index], "between": between_view(field.cameras, index)}
    truths = world_truths(field, panoramas, views, spp=spp)

    def true_error(env: str, view: str, image: RelitImage) -> float:
        radiance, seen = truths[(env, view)]
        return relative_rmse_values(image.radiance, radiance, image.needed & seen)

    models = models_for_field(field, models=PARAMETRIC_MODELS)
    return validate_advisor(name, field, models, views, true_error, panoramas,
                            samples=samples, tolerance=tolerance)  # fmt: skip


def world_field(fields_dir: Path, world: str, spec: tuple[int, int, int, int, int]) -> Path:
    """Render (once; cached in ``fields_dir``) a world's field; returns the store's path.

    ``spec`` is (cameras, lights, image side, samples per pixel, points); the lights lie on a
    Fibonacci lattice.
    """
    cameras, lights, side, spp, points = spec
    path = fields_dir / f"advise-world-{world}-{cameras}x{lights}-{side}px-{spp}spp-{points}.zarr"
    if not path.exists():
        render_world_field(path, world, lights=lights, points=points, spp=spp, layout="fibonacci",
                           cameras=field_cameras(cameras, width=side, height=side))  # fmt: skip
    return path


def real_panoramas(names: Sequence[PanoramaName] = ("courtyard", "studio")) -> dict[str, Panorama]:
    """The bundled real panoramas, reduced to :data:`PANORAMA_HEIGHT` rows."""
    return {
        name: panorama_from_array(
            downsample_panorama(read_panorama(panorama_path(name)).rgb, PANORAMA_HEIGHT),
            source=name,
        )
        for name in names
    }


def ratio_summary(rows: Sequence[Mapping[str, Any]], view: str | None = None) -> str:
    """How often predicted / true lies within :data:`RATIO` (the worse view, or ``view``)."""
    true = np.array([max(r["true"].values()) if view is None else r["true"][view] for r in rows])
    ratios = np.array([r["predicted"] for r in rows]) / np.maximum(true, 1e-6)
    within = float(np.mean((ratios <= RATIO) & (ratios >= 1.0 / RATIO)))
    return (
        f"predicted / true over {len(rows)} predictions ({view or 'worse view'}): median "
        f"{np.median(ratios):.2f}, quartiles {np.percentile(ratios, 25):.2f}-"
        f"{np.percentile(ratios, 75):.2f}; within {RATIO}x either way: {within:.0%}"
    )


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.advisor_world -o DIR --field STORE [--env NAME ...] [--spp N]``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--field", type=Path, required=True, help="a path-traced world field")
    parser.add_argument("--env", action="append", choices=get_args(PanoramaName),
                        help="bundled panorama (default courtyard)")  # fmt: skip
    parser.add_argument("--spp", type=int, default=256, help="samples per pixel of the truth")
    parser.add_argument("--samples", type=int, default=3000, help="the advisor's samples")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    field = ReflectanceField.open(args.field)
    panoramas = real_panoramas(args.env or ["courtyard"])
    name = _world_of(field)[0].name
    rows = validate_world_advisor(name, field, panoramas, samples=args.samples, spp=args.spp)
    args.output.mkdir(parents=True, exist_ok=True)
    summary = [ratio_summary(rows), ratio_summary(rows, "captured"), ratio_summary(rows, "between")]
    text = format_advisor(rows, chart=None) + "\n" + "\n\n".join(summary) + "\n"
    (args.output / "advisor_world.md").write_text(text)
    (args.output / "advisor_world.json").write_text(
        json.dumps({"rows": rows, "seconds": time.perf_counter() - start}, indent=2) + "\n"
    )
    print(text, end="")
    return 0


if __name__ == "__main__":
    from core.progress import drawing_bars

    with drawing_bars():  # the library's bars on stderr, as ``rig`` draws them
        status = main()
    raise SystemExit(status)
