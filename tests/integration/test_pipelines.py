"""Whole pipelines: the demo, and a capture on the simulated rig through to a relit view.

Each runs the real parts end to end (emulators driven by the real drivers, the dataset on
disk, field building, relighting) and checks what a user would look at.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from app.cli import main
from capture.dataset import Dataset
from capture.grid_plan import grid_plan
from capture.session import CaptureSession
from core.field_store import ReflectanceField
from core.sample_data import panorama_path, rti_capture_path
from processing.panorama import read_panorama
from processing.process_dataset import process_dataset
from processing.rti import open_field_or_rti
from render.engines.interpolated import RelightSettings
from render.engines.modes import most_accurate_mode, open_relighter
from sim.capture_sources import simulated_capture_sources
from sim.field import field_cameras, simulate_field
from sim.ground_truth import render_environment
from sim.scenes import build_scene
from sim.simulated_rig import SimulatedRig, simulated_capture_config


def test_demo_writes_pictures_and_report(tmp_path: Path) -> None:
    assert main(["demo", "--quick", "-o", str(tmp_path)]) == 0
    report = (tmp_path / "report.md").read_text()
    runs = sorted(p.name for p in (tmp_path / "sampling").iterdir())
    assert "tmed-k64" in runs and "paper-tmed-k64" in runs and len(runs) == 10
    for run in runs:
        assert run in report
        assert (tmp_path / "sampling" / run / "overlay.png").stat().st_size > 0
    for scene in ("glossy-sphere", "textured-torus"):
        for picture in ("ground-truth.png", "paper.png", "best.png", "rotating-environment.gif"):
            assert (tmp_path / "relight" / scene / picture).stat().st_size > 0
    assert (tmp_path / "relight" / "rti" / "studio.png").stat().st_size > 0
    assert "## Relighting simulated fields" in report
    assert "## Capture on the simulated rig" in report and "capture: success" in report
    assert (tmp_path / "capture" / "contact-sheet.png").stat().st_size > 0
    assert (tmp_path / "capture" / "dataset" / "manifest.json").exists()


def test_a_simulated_capture_relights_close_to_the_truth(tmp_path: Path) -> None:
    scene, points, size = "diffuse-sphere", 3000, 48
    config = simulated_capture_config(scene, size=size, points=points, speed=20.0)
    plan = grid_plan(4, 8, exposures_ms=(20.0,), layout="fibonacci")
    dataset = Dataset.create(
        tmp_path / "d", rig_config=config.to_dict(), plan=plan.to_dict(),
        planned=plan.planned_keys(config),
    )  # fmt: skip
    with SimulatedRig(config) as simulated, simulated.rig() as rig:
        result = CaptureSession(rig, dataset, plan).run()
    assert result.exit_status == "success"
    report = Dataset.open(tmp_path / "d").verify()
    assert report.ok and report.complete
    built = process_dataset(tmp_path / "d", tmp_path / "f.zarr", simulated_capture_sources(
        dataset.rig_config))  # fmt: skip
    assert built.shape == (4, 8, points)

    # The captured field agrees with the one the simulator writes directly.
    direct = tmp_path / "direct.zarr"
    simulate_field(direct, scene, lights=8, points=points, layout="fibonacci",
                   cameras=field_cameras(4, "fibonacci", width=size, height=size))  # fmt: skip
    a, b = ReflectanceField.open(tmp_path / "f.zarr"), ReflectanceField.open(direct)
    seen = (a.visibility & b.visibility)[:, None, :, None]
    measured, expected = a.load(), b.load()
    mask = np.broadcast_to(seen, measured.shape) & np.broadcast_to(
        np.ones(measured.shape[:2], bool)[:, :, None, None], measured.shape
    )
    skipped = [(c, t) for c, t, _ in plan.skipped(config)]
    for c, t in skipped:
        mask[c, t] = False
    error = np.sqrt(np.mean((measured[mask] - expected[mask]) ** 2) / np.mean(expected[mask] ** 2))
    assert error < 0.05

    # Relit at a view between the captured cameras, against the simulator's ground truth.
    panorama = read_panorama(panorama_path("courtyard"))
    camera = replace(a.cameras[1], azimuth_deg=(a.cameras[1].azimuth_deg + 20.0) % 360.0)
    truth = render_environment(build_scene(scene, points), panorama.rgb, camera, grid_height=32)
    engine = open_relighter(a, RelightSettings(scheme="pixels", interpolation="barycentric",
                                               view_interpolation="barycentric"))  # fmt: skip
    engine.set_lighting(panorama)
    engine.set_view(camera)
    image = engine.render()
    both = image.coverage & truth.coverage
    assert both.sum() > 0.8 * truth.coverage.sum()
    relit = np.sqrt(
        np.mean((image.rgb[both] - truth.rgb[both]) ** 2) / np.mean(truth.rgb[both] ** 2)
    )
    # 8 lights interpolated at a view between 4 cameras: about 23 % (a broken chain: ~100 %).
    assert relit < 0.35


def test_the_bundled_rti_capture_relights_under_both_panoramas() -> None:
    with open_field_or_rti(rti_capture_path()) as field:
        assert field.sample_kind == "pixels" and field.shape[1] == 240
        choice = most_accurate_mode(field)
        engine = open_relighter(field, choice.mode, choice.models)
        engine.set_view(field.cameras[0])
        images = []
        for name in ("courtyard", "studio"):
            engine.set_lighting(read_panorama(panorama_path(name)))
            images.append(engine.render().rgb)
    for rgb in images:
        assert np.isfinite(rgb).all() and rgb.max() > 0
    # Two different environments light the object differently.
    assert not np.allclose(images[0] / images[0].mean(), images[1] / images[1].mean(), rtol=0.05)
