"""``rig demo``: the demonstration pipeline (application layer, like :mod:`app.cli`).

On the bundled panorama: samples it with every sampler and several K, disassembles the light
and writes the pictures; then simulates reflectance fields of a glossy sphere and a textured
torus (30 cameras x 30 lights), relights them under the panorama with the paper's
configuration and with the most accurate one, beside the simulator's ground truth, and writes
the pictures, a rotating-environment GIF and the errors into the report. The simulated capture
rig joins it when it lands.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from core.atomic import atomic_path
from core.progress import progress_bar
from core.sample_data import panorama_path, rti_capture_path

if TYPE_CHECKING:
    from processing.panorama import Panorama
    from render.engines.modes import RelightMode

__all__ = ["DEMO_KS", "run_demo"]

DEMO_KS = (8, 64, 256)
DEMO_SCENES = ("glossy-sphere", "textured-torus")
DEMO_POINTS = 40_000
DEMO_SIZE = 256


def run_demo(directory: str | Path, *, quick: bool = False) -> Path:
    """Write the demo outputs under ``directory``; returns the path of ``report.md``.

    ``quick`` relights smaller fields (for smoke tests). Its steps are counted with bars
    (:mod:`core.progress`): ``rig demo`` draws them on the terminal.
    """
    import numpy as np

    from processing.environment import LightingControls
    from processing.panorama import read_panorama
    from processing.sampling import SAMPLERS
    from render.lighting_outputs import write_lighting_outputs

    out = Path(directory)
    panorama = read_panorama(panorama_path("courtyard"))
    runs: list[tuple[str, LightingControls]] = [
        (f"tmed-k{k}", LightingControls(k=k)) for k in DEMO_KS
    ]
    runs += [(f"{m}-k64", LightingControls(k=64, method=m)) for m in SAMPLERS if m != "tmed"]
    runs.append(("paper-tmed-k64", LightingControls(k=64, paper=True)))
    runs.append(("tmed-k64-yaw90", LightingControls(k=64, yaw_deg=90.0)))
    lines = [
        "# Demo report",
        "",
        f"Panorama: `{panorama.source}` ({panorama.width}x{panorama.height}).",
        "",
        "| run | K | seconds | total light R, G, B (radiance x sr) | pictures |",
        "|---|---|---|---|---|",
    ]
    for name, controls in progress_bar(runs, desc="sampling", unit="run"):
        start = time.perf_counter()
        lighting = write_lighting_outputs(panorama, controls, out / "sampling" / name)
        seconds = time.perf_counter() - start
        total = ", ".join(f"{v:.4f}" for v in np.sum(lighting.light_set().rgb, axis=0))
        lines.append(
            f"| {name} | {lighting.light_set().k} | {seconds:.3f} | {total} | "
            f"[overlay](sampling/{name}/overlay.png), [lights](sampling/{name}/lights.png) |"
        )
    lines += ["", "Every run gathers the same total light: disassembling conserves energy.", ""]
    from app.demo_capture import capture_demo

    lines += capture_demo(out, panorama, quick)
    lines += _relight_demo(out, panorama, quick)
    lines += _rti_demo(out)
    report = out / "report.md"
    with atomic_path(report) as temporary:
        temporary.write_text("\n".join(lines), encoding="utf-8")
    return report


def _relight_demo(out: Path, panorama: Panorama, quick: bool) -> list[str]:
    """Relight simulated fields; returns the report's lines."""
    import numpy as np

    from core.field_store import ReflectanceField
    from core.image_io import write_srgb8
    from render.engines.interpolated import RelightSettings, best_settings
    from render.engines.modes import most_accurate_mode, open_relighter
    from render.output import display_picture, write_sequence
    from render.relighting import RelightRequest, prepare_relighting
    from render.sequence import relight_sequence
    from render.tonemap import auto_exposure
    from sim.field import field_cameras, simulate_field
    from sim.ground_truth import render_environment
    from sim.scenes import build_scene, get_scene

    count, points, size = (12, 4000, 96) if quick else (30, DEMO_POINTS, DEMO_SIZE)
    lines = [
        "## Relighting simulated fields",
        "",
        f"{count} cameras x {count} lights, {points} points, a {size} x {size} view halfway "
        "between two captured cameras; error = relative RMSE over covered pixels against the "
        "simulator's ground truth (direct light, shadows).",
        "",
        "| scene | method | relative RMSE | relight + splat ms | picture |",
        "|---|---|---|---|---|",
    ]
    for scene in progress_bar(DEMO_SCENES, desc="relighting", unit="scene"):
        cameras = field_cameras(count, width=size, height=size)
        store = out / "fields" / f"{scene}.zarr"
        simulate_field(store, scene, lights=count, cameras=cameras, points=points, overwrite=True)
        field = ReflectanceField.open(store)
        captured = cameras[count // 2]
        view = replace(captured, azimuth_deg=(captured.azimuth_deg + 15.0) % 360.0)
        samples = build_scene(scene, points)
        truth = render_environment(samples, panorama.rgb, view, shadows=not get_scene(scene).convex)
        exposure = auto_exposure(truth.rgb[truth.coverage])
        folder = out / "relight" / scene
        write_srgb8(
            folder / "ground-truth.png", display_picture(truth.rgb, truth.coverage, exposure)
        )
        lines.append(
            f"| {scene} | ground truth | - | - | [png](relight/{scene}/ground-truth.png) |"
        )
        choice = most_accurate_mode(field)
        best = f"chosen by held-out lights: {choice.mode.describe(choice.models)}"
        methods: dict[str, tuple[str, RelightMode]] = {
            "paper": ("paper: TMED K=64, cosine 3x3, eq. 3", RelightSettings.paper_configuration()),
            "interpolated": ("eq. 2, barycentric", best_settings(field)),
            "best": (best, choice.mode),
        }
        for name, (label, mode) in methods.items():
            request = RelightRequest(panorama=panorama, camera=view, mode=mode)
            relighter = prepare_relighting(field, request, models=choice.models).engine
            start = time.perf_counter()
            image = relighter.render()
            ms = (time.perf_counter() - start) * 1e3
            mask = image.coverage & truth.coverage
            error = np.sqrt(
                np.mean((image.rgb[mask] - truth.rgb[mask]) ** 2) / np.mean(truth.rgb[mask] ** 2)
            )
            write_srgb8(
                folder / f"{name}.png", display_picture(image.rgb, image.coverage, exposure)
            )
            link = f"[png](relight/{scene}/{name}.png)"
            lines.append(f"| {scene} | {label} | {error:.2%} | {ms:.1f} | {link} |")
        relighter = open_relighter(field, choice.mode, choice.models)
        frames = relight_sequence(relighter, panorama, view, frames=12, display_exposure=exposure)
        write_sequence(folder / "rotating-environment.gif", frames, fps=6)
        link = f"[gif](relight/{scene}/rotating-environment.gif)"
        lines.append(f"| {scene} | best, environment rotating | - | - | {link} |")
    return [*lines, ""]


def _rti_demo(out: Path) -> list[str]:
    """Relight the real RTI capture under both bundled panoramas; returns the report's lines."""
    import numpy as np

    from core.image_io import write_srgb8
    from processing.panorama import read_panorama
    from processing.rti import open_field_or_rti
    from processing.sample_model_store import models_for_field
    from processing.sample_models import choose_model, format_loo_table, interpolation_loo
    from render.output import display_picture
    from render.relighting import ModeRequest, RelightRequest, relight_request

    lines = ["## Relighting a real RTI capture", ""]
    lp = rti_capture_path()
    lines += [
        f"The bundled capture `{lp.parent.name}` (240 lights, one view), imported as a "
        "single-view field and relit under the bundled panoramas (pictures enlarged 4x, "
        "nearest neighbour):",
        "",
    ]
    with open_field_or_rti(lp) as field:
        for name in ("courtyard", "studio"):
            # As rig relight CAPTURE --env PANO --fast does: the rung chosen under the panorama.
            panorama = read_panorama(panorama_path(name))
            request = RelightRequest(
                panorama=panorama, camera=field.cameras[0], mode=ModeRequest(fast=True)
            )
            relit = relight_request(field, request)
            picture = display_picture(relit.image.rgb, relit.image.coverage)
            target = out / "relight" / "rti" / f"{name}.png"
            write_srgb8(target, np.repeat(np.repeat(picture, 4, axis=0), 4, axis=1))
            lines.append(f"- under {name}: [png](relight/rti/{name}.png); {relit.chosen.reason}")
        models = models_for_field(field)
        lines += ["", "Leave-one-light-out error:", ""]
        lines.append(format_loo_table(choose_model(models).table, extra={
            f"interpolation: {m}": interpolation_loo(field, m).relative_rmse
            for m in ("nearest", "barycentric", "paper")
        }))  # fmt: skip
    return [*lines, ""]
