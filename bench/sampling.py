"""Benchmark of environment sampling and light disassembling.

Run: ``python -m bench.sampling -o bench-out`` (or ``make bench``). Prints tables and writes
``bench-out/sampling.json`` and ``bench-out/sampling.png``. Timings are the median of repeated
runs after numba compilation; each fast path is compared with a plain reference *in the same
run*, as a ratio, because absolute times on a shared 2-core machine are noisy.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.colour import luminance
from core.directions import panorama_directions, panorama_solid_angles
from core.sample_data import panorama_path
from processing.environment import LightingControls, light_environment
from processing.halftone import DIFFUSION_METHODS, _diffuse, _method_tables, error_diffuse
from processing.image_quality import relative_rmse_values
from processing.lights import disassemble_lights
from processing.panorama import panorama_from_array, read_panorama
from processing.sampling import SAMPLERS, sample_environment

KS = (8, 16, 32, 64, 128, 256, 512, 1024)


def _median_seconds(run: Callable[[], object], repeats: int) -> float:
    run()  # compile / warm caches
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _reference_disassemble(
    rgb: NDArray[np.float32], directions: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Plain numpy/scipy: k-d tree nearest sample, then bincount per channel."""
    height, width = rgb.shape[:2]
    labels = cKDTree(directions).query(panorama_directions(height, width).reshape(-1, 3))[1]
    weighted = (rgb * panorama_solid_angles(height, width)[:, :, None]).reshape(-1, 3)
    k = directions.shape[0]
    return np.stack([np.bincount(labels, weighted[:, c], minlength=k) for c in range(3)], axis=1)


def bench_diffusion(rgb: NDArray[np.float32], repeats: int) -> list[dict[str, Any]]:
    """Raw error-diffusion kernel on a 2048 x 1024 grey image vs. its pure-Python form."""
    big = cv2.resize(rgb, (2048, 1024), interpolation=cv2.INTER_LINEAR)
    grey = luminance(np.asarray(big, dtype=np.float32)).astype(np.float64)
    grey = np.clip(grey / np.percentile(grey, 99), 0, 1)  # a halftone-able grey image
    crop = np.ascontiguousarray(grey[448:576, 896:1152])  # 256 x 128 for the slow reference
    rows = []
    for method in DIFFUSION_METHODS:
        seconds = _median_seconds(partial(error_diffuse, grey, method=method), repeats)
        weights, modulation = _method_tables(method)
        threshold = 127 << 16 if method == "tmed" else (255 << 16) // 2

        fired = np.zeros(crop.shape, dtype=np.bool_)
        margin = np.empty(crop.shape, dtype=np.float32)
        start = time.perf_counter()
        with np.errstate(over="ignore"):  # the generator's uint32 wrap-around is intended
            _diffuse.py_func(crop, 16, weights, modulation, threshold, 0, fired, margin)
        python_per_pixel = (time.perf_counter() - start) / crop.size
        rows.append(
            {
                "method": method,
                "pixels": grey.size,
                "numba_ms": seconds * 1e3,
                "python_ms_extrapolated": python_per_pixel * grey.size * 1e3,
                "speedup": python_per_pixel * grey.size / seconds,
            }
        )
    return rows


def bench_sampling(rgb: NDArray[np.float32], repeats: int) -> list[dict[str, Any]]:
    """Whole samplers (density, grid, diffusion, refinement) at K = 64 on two sizes."""
    rows = []
    for width in (1024, 2048):
        image = np.asarray(cv2.resize(rgb, (width, width // 2)), dtype=np.float32)
        for method in SAMPLERS:
            seconds = _median_seconds(
                partial(sample_environment, image, 64, method=method), repeats
            )
            rows.append(
                {"method": method, "size": f"{width}x{width // 2}", "k": 64, "ms": seconds * 1e3}
            )
    return rows


def bench_disassembling(rgb: NDArray[np.float32], repeats: int) -> list[dict[str, Any]]:
    """Disassembling a 1024 x 512 panorama: pruned numba search vs. k-d tree + bincount."""
    rng = np.random.default_rng(0)
    rows = []
    for k in KS:
        d = rng.normal(size=(k, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        fast = _median_seconds(partial(disassemble_lights, rgb, d), repeats)
        reference = _median_seconds(partial(_reference_disassemble, rgb, d), max(2, repeats // 3))
        agree = np.allclose(
            disassemble_lights(rgb, d).rgb, _reference_disassemble(rgb, d), rtol=1e-9
        )
        rows.append(
            {
                "k": k,
                "numba_ms": fast * 1e3,
                "reference_ms": reference * 1e3,
                "speedup": reference / fast,
                "same_result": bool(agree),
            }
        )
    return rows


def bench_environment(rgb: NDArray[np.float32], repeats: int) -> dict[str, Any]:
    """New lighting end to end: yaw + sample (TMED) + disassemble, 1024 x 512, K = 64."""
    panorama = panorama_from_array(rgb)
    seconds = _median_seconds(
        lambda: light_environment(panorama, LightingControls(k=64, yaw_deg=33.0)), repeats
    )
    return {"size": f"{panorama.width}x{panorama.height}", "k": 64, "ms": seconds * 1e3}


def _lobe_responses(
    normals: NDArray[np.float64],
    directions: NDArray[np.float64],
    light: NDArray[np.float64],
    exponent: int,
) -> NDArray[np.float64]:
    """Sum over lights of light x max(0, n . w)^exponent for each normal; chunked over lights."""
    total = np.zeros(normals.shape[0])
    for start in range(0, directions.shape[0], 65536):
        cosine = np.maximum(normals @ directions[start : start + 65536].T, 0.0)
        total += (cosine**exponent) @ light[start : start + 65536]
    return total


def bench_accuracy(panoramas: list[Path]) -> list[dict[str, Any]]:
    """How well K disassembled lights reproduce a panorama's lighting, per sampler.

    Error = relative RMSE, over 500 normals spread on the sphere, of the luminance response to
    a cosine lobe (diffuse) and a Phong lobe of exponent 20 (glossy), lights against every pixel.
    """
    i = np.arange(500) + 0.5
    normals = np.stack(
        [
            np.sqrt(1 - (1 - 2 * i / 500) ** 2) * np.cos(np.pi * (3 - np.sqrt(5)) * i),
            np.sqrt(1 - (1 - 2 * i / 500) ** 2) * np.sin(np.pi * (3 - np.sqrt(5)) * i),
            1 - 2 * i / 500,
        ],
        axis=1,
    )
    configurations: list[tuple[str, dict[str, Any]]] = [(m, {"method": m}) for m in SAMPLERS]
    configurations.append(("tmed paper", {"paper": True}))
    configurations += [(f"tmed cells/sample={c:g}", {"cells_per_sample": c}) for c in (1, 4, 8)]
    rows = []
    for path in panoramas:
        rgb = read_panorama(path).rgb
        height, width = rgb.shape[:2]
        pixels = panorama_directions(height, width).reshape(-1, 3)
        energy = (luminance(rgb) * panorama_solid_angles(height, width)).ravel().astype(np.float64)
        truth = {p: _lobe_responses(normals, pixels, energy, p) for p in (1, 20)}
        for k in (16, 64, 256):
            for name, options in configurations:
                samples = sample_environment(rgb, k, **options)
                lights = disassemble_lights(rgb, samples.directions)
                light = luminance(lights.rgb.astype(np.float32)).astype(np.float64)
                row: dict[str, Any] = {"panorama": path.name, "k": k, "configuration": name}
                for exponent, label in ((1, "diffuse"), (20, "phong20")):
                    estimate = _lobe_responses(normals, lights.directions, light, exponent)
                    row[f"{label}_rel_rmse"] = relative_rmse_values(estimate, truth[exponent])
                rows.append(row)
    return rows


def _chart(results: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = results["disassembling"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    ks = [r["k"] for r in rows]
    left.loglog(ks, [r["numba_ms"] for r in rows], "o-", label="pruned blocks (numba)")
    left.loglog(ks, [r["reference_ms"] for r in rows], "s--", label="k-d tree + bincount")
    left.axhline(20, color="grey", lw=0.8, ls=":", label="goal 20 ms")
    left.set(xlabel="K lights", ylabel="ms", title="Disassembling 1024x512")
    left.legend()
    sampling = [r for r in results["sampling"] if r["size"] == "1024x512"]
    right.bar([r["method"] for r in sampling], [r["ms"] for r in sampling])
    right.set(ylabel="ms", title="Sampling 1024x512, K = 64")
    right.tick_params(axis="x", rotation=30)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.sampling [-o DIR] [--repeats N] [--panorama EXR]``; the exit status.

    ``--accuracy-panoramas`` lists the panoramas of the accuracy table (missing files are
    skipped with a note). Writes ``DIR/sampling.json`` and ``DIR/sampling.png``.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("-o", "--output", type=Path, default=Path("bench-out"))
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--panorama", type=Path, default=panorama_path("courtyard"))
    parser.add_argument(
        "--accuracy-panoramas",
        type=Path,
        nargs="*",
        default=[panorama_path("courtyard"), panorama_path("studio")],
        help="panoramas for the accuracy table (missing files are skipped with a note)",
    )
    args = parser.parse_args(argv)
    accuracy_panoramas = [p for p in args.accuracy_panoramas if p.is_file()]
    for missing in set(args.accuracy_panoramas) - set(accuracy_panoramas):
        print(f"note: {missing} not found; left out of the accuracy table")
    rgb = read_panorama(args.panorama).rgb
    results: dict[str, Any] = {
        "machine": {"cpu_count": __import__("os").cpu_count(), "python": platform.python_version()},
        "panorama": str(args.panorama),
        "diffusion": bench_diffusion(rgb, args.repeats),
        "sampling": bench_sampling(rgb, args.repeats),
        "disassembling": bench_disassembling(rgb, args.repeats),
        "environment": bench_environment(rgb, args.repeats),
        "accuracy": bench_accuracy(accuracy_panoramas),
    }
    print("error diffusion, 2048x1024 grey image (raw kernel)")
    for r in results["diffusion"]:
        print(
            f"  {r['method']:16s} {r['numba_ms']:7.1f} ms"
            f"   pure Python {r['python_ms_extrapolated']:9.0f} ms"
            f"   x{r['speedup']:.0f}"
        )
    print("whole samplers, K = 64")
    for r in results["sampling"]:
        print(f"  {r['method']:16s} {r['size']:10s} {r['ms']:7.1f} ms")
    print("disassembling 1024x512")
    for r in results["disassembling"]:
        print(
            f"  K={r['k']:5d} {r['numba_ms']:7.2f} ms   k-d tree {r['reference_ms']:7.1f} ms"
            f"   x{r['speedup']:.1f}   same result: {r['same_result']}"
        )
    env = results["environment"]
    print(f"new lighting (yaw + TMED + disassemble), {env['size']}, K=64: {env['ms']:.1f} ms")
    print("accuracy of K lights against every pixel (relative RMSE, diffuse / phong-20 lobes)")
    for r in results["accuracy"]:
        print(
            f"  {r['panorama']:14s} K={r['k']:4d} {r['configuration']:24s}"
            f" {r['diffuse_rel_rmse']:.4f} / {r['phong20_rel_rmse']:.4f}"
        )
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "sampling.json").write_text(json.dumps(results, indent=2) + "\n")
    _chart(results, args.output / "sampling.png")
    print(f"wrote {args.output / 'sampling.json'} and {args.output / 'sampling.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
