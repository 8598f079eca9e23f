"""The capture half of the demo: the simulated rig, a sweep, verify, process, relight.

The emulators run on pseudo-terminals and the real drivers drive them; the simulated camera
renders the synthetic object at the rig's measured pose. The captured dataset is verified,
processed into a reflectance field (compared with the field the simulator writes directly),
and relit under the panorama at several K and views beside the ground truth.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from core.errors import RigError

if TYPE_CHECKING:
    from processing.panorama import Panorama
    from render.engines.interpolated import RelitImage
    from sim.synthetic_camera import SyntheticImage

__all__ = ["capture_demo"]

DEMO_SCENE = "glossy-sphere"


def capture_demo(out: Path, panorama: Panorama, quick: bool) -> list[str]:
    """Run the capture pipeline into ``out/capture``; returns the report's lines."""
    from capture.dataset import Dataset
    from capture.grid_plan import grid_plan
    from capture.session import CaptureSession
    from processing.process_dataset import process_dataset
    from sim.capture_sources import simulated_capture_sources
    from sim.simulated_rig import SimulatedRig, simulated_capture_config

    quick_setup, full_setup = (3, 5, 96, 2000, 20.0), (12, 12, 256, 20_000, 4.0)
    cameras, lights, size, points, speed = quick_setup if quick else full_setup
    config = simulated_capture_config(DEMO_SCENE, size=size, points=points, speed=speed)
    # A bracket: the glossy highlight saturates 40 ms exposures; the HDR merge recovers it.
    plan = grid_plan(cameras, lights, exposures_ms=(40.0, 4.0), layout="fibonacci")
    root = out / "capture"
    dataset_path, field_path = root / "dataset", root / "field.zarr"
    if dataset_path.exists():
        import shutil

        shutil.rmtree(root)
    dataset = Dataset.create(
        dataset_path,
        rig_config=config.to_dict(),
        plan=plan.to_dict(),
        planned=plan.planned_keys(config),
    )
    estimate = plan.estimate(config)
    with SimulatedRig(config) as simulated, simulated.rig() as rig:
        result = CaptureSession(rig, dataset, plan).run()
    seconds = result.seconds
    modelled = estimate.motion_by_ordering_s[plan.ordering]
    report = Dataset.open(dataset_path).verify()
    started = time.perf_counter()
    process_dataset(dataset_path, field_path, simulated_capture_sources(config.to_dict()))
    process_s = time.perf_counter() - started
    lines = [
        "## Capture on the simulated rig",
        "",
        f"Dynamixel and GRBL emulators on pseudo-terminals, driven by the real drivers; "
        f"{DEMO_SCENE}, {points} points, {cameras} cameras x {lights} lights (fibonacci), "
        f"{size} x {size} images, axes at {speed:g}x the simulated rig's speed.",
        "",
        f"- capture: {result.exit_status}, {result.taken} images "
        f"({len(plan.skipped(config))} camera-light pairs skipped by the plan) in "
        f"{seconds['total']:.1f} s: moving {seconds['move']:.1f} s (the motion model "
        f"predicts {modelled:.1f} s), camera (render + sensor) {seconds['capture']:.1f} s, "
        f"storing {seconds['store']:.1f} s, light switching {seconds['light']:.1f} s",
        f"- verify: {report.summary()}",
        f"- process (as `rig process`): {process_s:.1f} s -> `capture/field.zarr`",
    ]
    skipped = [(c, t) for c, t, _ in plan.skipped(config)]
    lines += _agreement(root, field_path, cameras, lights, points, size, skipped)
    lines += _relight_captured(out, field_path, panorama, quick)
    lines += _advise_captured(field_path, panorama, quick, cameras, lights)
    return [*lines, ""]


def _advise_captured(
    field_path: Path, panorama: Panorama, quick: bool, cameras: int, lights: int
) -> list[str]:
    """``rig advise`` and ``rig plan --advise`` on the captured field, as report lines.

    With the choice's true error at a view between the captured cameras.
    """
    from core.field_store import ReflectanceField
    from processing.sample_model_store import models_for_field
    from render.advisor import Advisor, capture_density
    from render.relighting import RelightRequest, relight_request
    from sim.ground_truth import render_environment
    from sim.scenes import build_scene

    field = ReflectanceField.open(field_path)
    tolerance = 0.05
    try:
        advice = Advisor(field, samples=800 if quick else 2000).advise(panorama, tolerance)
    except RigError as error:  # the quick demo's 5 lights are too few to hold out
        return ["", f"`rig advise` on the captured field: {error}"]
    lines = ["", f"`rig advise` on the captured field (tolerance {tolerance:.0%}):", "", "```"]
    lines += [advice.format(), "```", ""]
    if advice.choice is not None:
        size = 96 if quick else 256
        middle = field.cameras[len(field.cameras) // 2]
        camera = replace(middle, azimuth_deg=(middle.azimuth_deg + 20.0) % 360.0, width=size,
                         height=size)  # fmt: skip
        samples = build_scene(DEMO_SCENE, field.shape[2])
        truth = render_environment(samples, panorama.rgb, camera, grid_height=64)
        request = RelightRequest(
            panorama=panorama, camera=camera, mode=advice.choice.candidate.mode
        )
        relit = relight_request(field, request, models=models_for_field(field))
        relit_error = _image_error(relit.image, truth)
        lines.append(
            f"The choice relit at a view between the captured cameras: {relit_error:.2%} against "
            f"the ground truth (image; predicted {advice.choice.error:.2%} over the samples)."
        )
    try:
        density = capture_density(advice, cameras, lights)
    except RigError as error:
        lines.append(f"`rig plan --advise`: {error}")
    else:
        lines.append(
            f"`rig plan --advise`: {density.cameras} cameras x {density.lights} lights for "
            f"{density.candidate.name} ({density.reason})."
        )
    return lines


def _agreement(
    root: Path,
    field_path: Path,
    cameras: int,
    lights: int,
    points: int,
    size: int,
    skipped: list[tuple[int, int]],
) -> list[str]:
    """The captured field against the one the simulator writes directly."""
    from core.field_store import ReflectanceField
    from processing.image_quality import relative_rmse_values
    from sim.field import field_cameras, simulate_field

    direct_path = root / "direct.zarr"
    layout = field_cameras(cameras, "fibonacci", width=size, height=size)
    simulate_field(direct_path, DEMO_SCENE, lights=lights, cameras=layout, points=points,
                   layout="fibonacci", overwrite=True)  # fmt: skip
    built, direct = ReflectanceField.open(field_path), ReflectanceField.open(direct_path)
    both = built.visibility & direct.visibility
    a, b = built.load(), direct.load()
    measured = np.ones(a.shape[:2], dtype=bool)
    for c, t in skipped:
        measured[c, t] = False

    def relative_rmse(pairs: np.ndarray) -> float:
        return relative_rmse_values(a, b, pairs[:, :, None] & both[:, None, :])

    agree = float((built.visibility == direct.visibility).mean())
    filled = f"{relative_rmse(~measured):.2%}" if (~measured).any() else "-"
    return [
        f"- the captured field against `rig sim field` of the same scene and layout: relative "
        f"RMSE {relative_rmse(measured):.2%} over the measured (camera, light) pairs and the "
        f"samples both see, {filled} over the {len(skipped)} pairs the plan skipped (the light "
        f"where the camera stands: interpolated from the camera's other lights, which misses "
        f"the backscatter peak); visibility agrees on {agree:.2%}",
        "",
    ]


def _relight_captured(out: Path, field_path: Path, panorama: Panorama, quick: bool) -> list[str]:
    """Relight the captured field at several K and views; pictures, a contact sheet, errors."""
    from core.field_store import ReflectanceField
    from core.image_io import write_srgb8
    from render.engines.interpolated import RelightSettings
    from render.engines.models import ModelRelightSettings
    from render.engines.modes import RelightMode, most_accurate_mode
    from render.output import display_picture
    from render.relighting import RelightRequest, relight_request
    from render.tonemap import auto_exposure
    from sim.ground_truth import render_environment
    from sim.scenes import build_scene

    field = ReflectanceField.open(field_path)
    choice = most_accurate_mode(field)
    size = 96 if quick else 256
    samples = build_scene(DEMO_SCENE, field.shape[2])
    captured = replace(field.cameras[len(field.cameras) // 2], width=size, height=size)
    views = {
        "between": replace(captured, azimuth_deg=(captured.azimuth_deg + 20.0) % 360.0),
        "high": replace(captured, inclination_deg=20.0),
    }
    methods: dict[str, RelightMode] = {"paper-k64": RelightSettings.paper_configuration(64)}
    for k in (8, 64, 256):
        methods[f"models-k{k}"] = ModelRelightSettings(lighting="sampled", k=k)
    methods["best"] = choice.mode
    lines = [
        f"Relit from the captured field ({choice.reason}); relative RMSE against the "
        "simulator's ground truth over covered pixels:",
        "",
        "| view | " + " | ".join(methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    tiles = []
    for view_name, camera in views.items():
        truth = render_environment(samples, panorama.rgb, camera, grid_height=64)
        exposure = auto_exposure(truth.rgb[truth.coverage])
        row = [_labelled(display_picture(truth.rgb, truth.coverage, exposure), "ground truth")]
        cells = []
        for name, mode in methods.items():
            request = RelightRequest(panorama=panorama, camera=camera, mode=mode)
            image = relight_request(field, request, models=choice.models).image
            error = _image_error(image, truth)
            picture = display_picture(image.rgb, image.coverage, exposure)
            write_srgb8(out / "capture" / "relit" / f"{view_name}-{name}.png", picture)
            row.append(_labelled(picture, f"{name} {error:.1%}"))
            cells.append(f"[{error:.2%}](capture/relit/{view_name}-{name}.png)")
        lines.append(f"| {view_name} | " + " | ".join(cells) + " |")
        tiles.append(np.concatenate(row, axis=1))
    sheet = np.concatenate(tiles, axis=0)
    write_srgb8(out / "capture" / "contact-sheet.png", sheet)
    return [*lines, "", "Contact sheet: [capture/contact-sheet.png](capture/contact-sheet.png)"]


def _image_error(image: RelitImage, truth: SyntheticImage) -> float:
    """Relative RMSE of a relit image against the ground truth over the pixels both cover."""
    from processing.image_quality import relative_rmse_values

    return relative_rmse_values(image.rgb, truth.rgb, image.coverage & truth.coverage)


def _labelled(picture: NDArray[np.uint8], text: str) -> NDArray[np.uint8]:
    """The picture with a caption drawn in its top-left corner."""
    import cv2

    tile = np.ascontiguousarray(picture.copy())
    scale = max(tile.shape[0] / 400.0, 0.3)
    cv2.putText(tile, text, (4, int(14 * scale) + 4), cv2.FONT_HERSHEY_SIMPLEX, scale,
                (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
    return tile
