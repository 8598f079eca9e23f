"""Where relighting fails: each failure case measured against the simulator, with its warning.

Run: ``python -m bench.stability -o DIR [--quick]``. For every case (a sun with few lights, a
sun's highlight on a sparse field, views outside the cameras or grazing, an LDR panorama, a
saturated or noisy capture, an empty camera, a missing camera pose) a small simulated field is
relit in a failing and in a benign configuration by the best interpolation
(:func:`render.engines.interpolated.best_settings`), the paper's configuration and the
per-sample models (:data:`render.engines.modes.MOST_ACCURATE_MODELS`); each row holds the
relative RMSE against the simulator's ground truth and the codes of the warnings
:func:`render.guards.relight_warnings` gives for that relighting (what ``rig relight``
prints). Writes ``DIR/stability.json`` and the table ``DIR/stability.md``; fields are
simulated into ``DIR/fields/`` once and reused.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bench.sim_truth import image_errors, truth_of
from capture.dataset import Dataset, ImageKey
from core.camera_model import PinholeCamera, RigCamera
from core.colour import luminance
from core.directions import panorama_solid_angles
from core.errors import DatasetError
from core.field_store import ReflectanceField
from core.sample_data import panorama_path
from processing.field_layout import field_layout
from processing.panorama import panorama_from_array, read_panorama
from processing.sample_models import SampleModels, fit_sample_models
from render.engines.interpolated import RelightSettings, best_settings
from render.engines.modes import MOST_ACCURATE_MODELS, RelightMode, open_relighter
from render.guards import relight_warnings
from sim.field import field_cameras, simulate_field
from sim.scenes import build_scene, get_scene
from sim.sensor import Sensor, expose, radiance_from_dn
from sim.skies import ldr_photo, procedural_sky

__all__ = [
    "METHODS",
    "energy_matched_ldr",
    "format_stability",
    "in_memory",
    "main",
    "measure",
    "run_stability",
    "sensor_field",
]

#: The relightings compared in every configuration.
METHODS: dict[str, Callable[[ReflectanceField], RelightMode]] = {
    "best interpolation": best_settings,
    "paper": lambda _field: RelightSettings.paper_configuration(64),
    "models": lambda _field: MOST_ACCURATE_MODELS,
}

#: Rows of the test panoramas (64 x 128: the ground truth's own pre-filter size).
SKY_HEIGHT = 64


@dataclass(frozen=True)
class Sizes:
    """Field and image sizes of a run."""

    points: int
    image: int


def _field(out: Path, scene: str, cameras: int, lights: int, sizes: Sizes) -> ReflectanceField:
    path = out / "fields" / f"{scene}-S{cameras}-T{lights}-{sizes.points}-{sizes.image}px.zarr"
    if not path.exists():
        layout = field_cameras(cameras, width=sizes.image, height=sizes.image)
        simulate_field(path, scene, lights=lights, cameras=layout, points=sizes.points)
    return ReflectanceField.open(path)


def in_memory(field: ReflectanceField, radiance: NDArray[np.floating]) -> ReflectanceField:
    """A copy of ``field`` held in memory with other radiance (S, T, P, 3): a changed capture.

    Its path is its own, as a subset's is: nothing saved beside the store belongs to it.
    """
    return replace(
        field,
        path=field.path.with_name(field.path.name + "[changed]"),
        radiance=np.asarray(radiance, dtype=np.float32),
        # What the writer recorded of the old radiance does not hold for the new one.
        radiance_digest=None,
        dark_cameras=None,
        cached_slabs=field.shape[0],
        _slabs=OrderedDict(),
    )


def sensor_field(field: ReflectanceField, level: float, seed: int = 0) -> ReflectanceField:
    """``field`` as a single-exposure capture through the simulated sensor (:mod:`sim.sensor`).

    The exposure puts the 99.9th percentile of the visible radiance at ``level`` times the full
    well: above 1 the brightest observations clip; far below 1 photon and read noise dominate.
    Every (camera, light) image is exposed with Poisson and read noise and read back as
    radiance, as :mod:`processing.field_builder` would from a one-exposure capture.
    """
    radiance = field.load().astype(np.float64)
    visible = np.broadcast_to(field.visibility[:, None, :, None], radiance.shape)
    top = float(np.percentile(radiance[visible], 99.9))
    base = Sensor()
    sensor = replace(base, exposure_s=level * base.full_well / (base.sensitivity * top))
    s_count, t_count, p_count, _ = radiance.shape
    digital = expose(radiance.reshape(s_count * t_count, p_count, 3), sensor, seed)
    measured = radiance_from_dn(digital, sensor).reshape(radiance.shape)
    return in_memory(field, np.where(visible, measured, 0.0))


def energy_matched_ldr(rgb: NDArray[np.floating]) -> NDArray[np.float32]:
    """The LDR photo of a panorama (:func:`sim.skies.ldr_photo`) scaled to its total light.

    The exposure a careful user would set, so the error left is the clipped sun's, not a
    brightness mismatch.
    """
    ldr = ldr_photo(rgb)
    omega = panorama_solid_angles(*ldr.shape[:2])
    total = float(np.sum(luminance(np.asarray(rgb, dtype=np.float32)) * omega))
    return (ldr * np.float32(total / float(np.sum(luminance(ldr) * omega)))).astype(np.float32)


def measure(
    field: ReflectanceField,
    scene: str,
    relit: NDArray[np.float32],
    camera: PinholeCamera,
    *,
    truth_rgb: NDArray[np.float32] | None = None,
    models: SampleModels | None = None,
    points: int,
) -> list[dict[str, Any]]:
    """Relative RMSE of every method of :data:`METHODS` and the warnings each gets.

    Parameters
    ----------
    field : the (possibly damaged) field relit
    scene : the simulated scene the truth is rendered from, with ``points`` samples
    relit : ndarray, shape (H, 2H, 3), the panorama given to the relighting
    camera : the view
    truth_rgb : ndarray, shape (H, 2H, 3), optional; the real lighting (default ``relit``)
    models : the field's fit (default: fitted here)

    Returns
    -------
    list of dict: method, relative_rmse, sample_relative_rmse, warnings (codes), messages
    """
    samples = build_scene(scene, points)
    truth = truth_of(
        samples, relit if truth_rgb is None else truth_rgb, camera, not get_scene(scene).convex
    )
    fit = fit_sample_models(field) if models is None else models
    panorama = panorama_from_array(relit, source="stability")
    rows = []
    for method, mode_of in METHODS.items():
        mode = mode_of(field)
        engine = open_relighter(field, mode, fit)
        engine.set_lighting(panorama)
        engine.set_view(camera)
        errors = image_errors(engine.render(), truth)
        warnings = relight_warnings(field, camera, relit, mode, fit)
        rows.append(
            {
                "method": method,
                "relative_rmse": errors["relative_rmse"],
                "sample_relative_rmse": errors["sample_relative_rmse"],
                "warnings": [w.code for w in warnings],
                "messages": [w.message for w in warnings],
            }
        )
    return rows


def _sky(sun_share: float) -> NDArray[np.float32]:
    return procedural_sky(SKY_HEIGHT, sun_share=sun_share, sun_inclination_deg=40.0)


def _missing_pose(out: Path) -> list[dict[str, Any]]:
    """A dataset whose camera pose record lacks its angles: processing must refuse it."""
    root = out / "missing-pose"
    if root.exists():
        import shutil

        shutil.rmtree(root)
    dataset = Dataset.create(root, rig_config={"camera": {}}, plan={"kind": "stability"})
    poses = {
        "complete": {"camera_azimuth_deg": 0.0, "camera_inclination_deg": 45.0,
                     "light_azimuth_deg": 90.0, "light_inclination_deg": 30.0},
        "missing": {"light_azimuth_deg": 90.0, "light_inclination_deg": 30.0},
    }  # fmt: skip
    rows = []
    for index, (name, pose) in enumerate(poses.items()):
        dataset.write_image(
            f"light_c{index}_l0_e0.png",
            b"not decoded: the layout is built first",
            key=ImageKey("light", index, 0, 0),
            exposure_ms=10.0,
            commanded_pose=poses["complete"],
            measured_pose=pose,
        )
        try:
            field_layout(dataset, camera=RigCamera(4.0, 40.0, 64, 64))
            outcome = "—"
        except DatasetError as error:
            outcome = f"DatasetError: {error}"
        rows.append({"configuration": f"camera pose {name}", "outcome": outcome})
    return rows


def _case(
    results: list[dict[str, Any]],
    case: str,
    configuration: str,
    failing: bool,
    rows: list[dict[str, Any]],
) -> None:
    for row in rows:
        results.append({"case": case, "configuration": configuration, "failing": failing} | row)
        codes = ", ".join(row["warnings"]) or "—"
        print(f"  {configuration:48s} {row['method']:20s} {row['relative_rmse']:7.2%}  {codes}")


def run_stability(out: Path, quick: bool) -> dict[str, Any]:
    """Sweep every failure case; write ``out/stability.json`` and ``out/stability.md``.

    Parameters
    ----------
    out : Path, the output directory (fields are kept in ``out/fields``)
    quick : bool, smaller fields and images (about a minute on two cores with the fields
        to simulate; the full run under two minutes)

    Returns
    -------
    dict: ``sizes``, ``rows`` (case, configuration, failing, method, relative_rmse,
    sample_relative_rmse, warnings, messages), ``missing_pose``, ``seconds``
    """
    started = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    sizes = Sizes(2000, 64) if quick else Sizes(3000, 96)
    rows: list[dict[str, Any]] = []
    sun, no_sun = _sky(0.9), _sky(0.0)
    courtyard = read_panorama(panorama_path("courtyard")).rgb

    def field(scene: str, cameras: int, lights: int) -> ReflectanceField:
        return _field(out, scene, cameras, lights, sizes)

    def run(case: str, configuration: str, failing: bool, *args: Any, **kwargs: Any) -> None:
        _case(rows, case, configuration, failing, measure(*args, points=sizes.points, **kwargs))

    print("sun with few lights (diffuse sphere, sky with 90 % in its sun)")
    for lights, failing in ((10, True), (30, False)):
        f = field("diffuse-sphere", 12, lights)
        view = f.cameras[len(f.cameras) // 2]
        run("sun, few lights", f"T={lights}, captured view", failing, f, "diffuse-sphere", sun,
            view)  # fmt: skip

    print("sun on a glossy sphere (GGX alpha 0.2)")
    sparse, dense = field("glossy-sphere", 12, 30), field("glossy-sphere", 6, 200)
    run("sun, glossy", "T=30, captured view", True, sparse, "glossy-sphere", sun,
        sparse.cameras[len(sparse.cameras) // 2])  # fmt: skip
    view = dense.cameras[len(dense.cameras) // 2]
    run("sun, glossy", "T=200, captured view", False, dense, "glossy-sphere", sun, view)
    if not quick:
        off = replace(view, azimuth_deg=view.azimuth_deg + 6.0)
        run("sun, glossy", "T=200, view 6 deg azimuth off a camera", True, dense,
            "glossy-sphere", sun, off)  # fmt: skip

    print("specular lobe on a sparse field, sky without sun")
    for f, lights, failing in ((sparse, 30, True), (dense, 200, False)):
        run("ghosting", f"T={lights}, captured view", failing, f, "glossy-sphere", no_sun,
            f.cameras[len(f.cameras) // 2])  # fmt: skip

    print("views outside the captured cameras (glossy sphere, courtyard)")
    fit = fit_sample_models(sparse)
    inside = replace(sparse.cameras[6], azimuth_deg=sparse.cameras[6].azimuth_deg + 10.0)
    below = PinholeCamera(20.0, 120.0, 4.0, 40.0, sizes.image, sizes.image)
    run("view outside", "from below (inclination 120)", True, sparse, "glossy-sphere",
        courtyard, below, models=fit)  # fmt: skip
    run("view outside", "10 deg from a camera", False, sparse, "glossy-sphere", courtyard,
        inside, models=fit)  # fmt: skip

    print("grazing views (glossy sphere, lowest camera ring at 67.5 deg, sky without sun)")
    for inclination, failing in ((85.0, True), (50.0, False)):
        view = PinholeCamera(20.0, inclination, 4.0, 40.0, sizes.image, sizes.image)
        run("grazing view", f"inclination {inclination:.0f}", failing, sparse, "glossy-sphere",
            no_sun, view, models=fit)  # fmt: skip

    print("LDR panorama that clips the sun (diffuse sphere, T=30)")
    matte = field("diffuse-sphere", 12, 30)
    view = matte.cameras[len(matte.cameras) // 2]
    matte_fit = fit_sample_models(matte)
    run("LDR panorama", "8-bit photo, energy matched", True, matte, "diffuse-sphere",
        energy_matched_ldr(sun), view, truth_rgb=sun, models=matte_fit)  # fmt: skip
    run("LDR panorama", "HDR", False, matte, "diffuse-sphere", sun, view, models=matte_fit)

    print("saturated capture (glossy sphere, T=30, one exposure)")
    view = sparse.cameras[len(sparse.cameras) // 2]
    for level, failing in ((3.0, True), (0.8, False)):
        run("saturated capture", f"99.9th percentile at {level:g} x full well", failing,
            sensor_field(sparse, level), "glossy-sphere", courtyard, view)  # fmt: skip

    print("noisy capture (diffuse sphere, T=30, one exposure)")
    view = matte.cameras[len(matte.cameras) // 2]
    for level, failing in ((0.002, True), (0.8, False)):
        run("noisy capture", f"99.9th percentile at {level:g} x full well", failing,
            sensor_field(matte, level), "diffuse-sphere", sun, view)  # fmt: skip

    print("empty camera slab (glossy sphere, T=30, courtyard, view at camera 5)")
    damaged = sparse.load().astype(np.float32)
    damaged[5] = 0.0
    run("empty camera", "camera 5 never written", True, in_memory(sparse, damaged),
        "glossy-sphere", courtyard, sparse.cameras[5])  # fmt: skip
    run("empty camera", "complete", False, sparse, "glossy-sphere", courtyard,
        sparse.cameras[5], models=fit)  # fmt: skip

    print("missing camera pose (dataset record without its camera angles)")
    missing = _missing_pose(out)
    for row in missing:
        print(f"  {row['configuration']:48s} {row['outcome']}")
    results = {
        "sizes": {"points": sizes.points, "image": sizes.image},
        "rows": rows,
        "missing_pose": missing,
        "seconds": time.perf_counter() - started,
    }
    (out / "stability.json").write_text(json.dumps(results, indent=2) + "\n")
    (out / "stability.md").write_text(format_stability(results))
    return results


def format_stability(results: dict[str, Any]) -> str:
    """A Markdown table: case, configuration, method, relative RMSE, warning codes or "—"."""
    sizes = results["sizes"]
    out = [
        f"Relative RMSE against the simulator's ground truth ({sizes['points']} points, "
        f"{sizes['image']} px images); warnings as `rig relight` gives them.",
        "",
        "| case | configuration | method | error | warning |",
        "|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        codes = ", ".join(row["warnings"]) or "—"
        out.append(
            f"| {row['case']} | {row['configuration']}{'' if row['failing'] else ' (benign)'} "
            f"| {row['method']} | {row['relative_rmse']:.2%} | {codes} |"
        )
    for row in results.get("missing_pose", []):
        out.append(f"| missing camera pose | {row['configuration']} | processing | - | "
                   f"{row['outcome']} |")  # fmt: skip
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.stability [-o DIR] [--quick]``; returns the exit status."""
    parser = argparse.ArgumentParser(description="Where relighting fails, measured")
    parser.add_argument("-o", "--output", type=Path, default=Path("bench-out"))
    parser.add_argument("--quick", action="store_true", help="smaller fields and images")
    args = parser.parse_args(argv)
    results = run_stability(args.output, args.quick)
    print(format_stability(results))
    print(f"wrote {args.output / 'stability.json'} in {results['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
