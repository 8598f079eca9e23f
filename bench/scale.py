"""The scale benchmark: build, fit and relight fields of growing size, in-process and on Dask.

``python -m bench.scale -o DIR [--sizes 250000,1000000,2000000] [--grid 30] [--workers 2]
[--worker-memory 2G] [--max-memory 700M]`` simulates a glossy sphere of each size (``--grid``
lights x cameras, float16), then runs each stage as its own process, the way a user runs it:

- ``build``: ``rig sim field`` (the simulator writing the store slab by slab);
- ``fit``: ``rig fit --max-memory`` in-process;
- ``fit on cluster``: the same fit as Dask tasks on a ``LocalCluster`` of ``--workers``
  processes, each limited to ``--worker-memory``, checked identical to the in-process fit;
- ``relight``: ``rig relight --scheme model`` from the saved fit (the exact grid sum).

For each it records the wall time, the throughput (samples per second), the stage process's
peak resident memory (``wait4``) and, on the cluster, each worker's peak. Writes
``scale.json`` and ``scale.png`` (cost and peak memory against size) and prints the table.
``--chunking`` instead measures the store's samples per chunk (``chunking.json``; see
:data:`core.field_store.SAMPLE_CHUNK`). Not a test: nothing is asserted about time.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from core.memory_budget import format_size, parse_size

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["cost_and_memory_chart", "main", "run_stage"]

SCENE = "glossy-sphere"
VIEW = "30,50"
SIZE = "512x512"


def run_stage(argv: list[str]) -> dict[str, Any]:
    """Run ``argv`` as a child process; its wall time (s) and peak resident memory (bytes).

    The peak is the largest of the process and the children it waited for (``wait4``).

    Raises RuntimeError with the child's last output when it fails.
    """
    start = time.perf_counter()
    child = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert child.stdout is not None
    output = child.stdout.read()
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({child.returncode}):\n{output[-3000:]}")
    return {"seconds": wall, "peak_bytes": usage.ru_maxrss * 1024, "output": output[-2000:]}


def _cluster_fit(args: argparse.Namespace) -> int:
    """``--stage cluster-fit``: fit on a LocalCluster, save, report the workers' peaks (JSON)."""
    from core.cluster import dask_client
    from core.field_store import ReflectanceField
    from processing.sample_model_store import write_sample_models
    from processing.sample_models import fit_sample_models

    field = ReflectanceField.open(args.store)
    with dask_client("local", workers=args.workers, memory_limit=args.worker_memory,
                     dashboard=False) as client:  # fmt: skip
        start = time.perf_counter()
        fitted = fit_sample_models(field, client=client)
        seconds = time.perf_counter() - start
        peaks = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    write_sample_models(args.output, fitted, field)
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"fit_seconds": seconds, "client_peak_bytes": own,
                      "worker_peak_bytes": sorted(peaks.values())}))  # fmt: skip
    return 0


def measure_chunking(
    directory: Path,
    points: int = 1_000_000,
    grid: int = 10,
    chunks: tuple[int, ...] = (16384, 65536, 262144),
) -> list[dict[str, Any]]:
    """Read and write speeds of the store per samples-per-chunk (and one chunk per slab).

    Slabs of a simulated glossy sphere (float16, as captures are stored) written ``grid`` x
    ``grid`` times through :class:`core.field_store.FieldStoreWriter`, then read the two ways
    the stages read: a camera's slabs (relighting) and a block of 65,536 samples under every
    camera and light (fitting, evaluation). MB/s of float16 radiance, best of three reads.
    """
    from core.field_store import FieldStoreWriter, ReflectanceField
    from sim.field import field_cameras, simulate_field

    source = directory / "chunking-source.zarr"
    simulate_field(source, SCENE, lights=2, cameras=field_cameras(2), points=points,
                   dtype="float16", overwrite=True)  # fmt: skip
    origin = ReflectanceField.open(source)
    slabs = [origin.camera_radiance(s) for s in range(2)]  # (2, P, 3) each
    cameras = field_cameras(grid)
    rows = []
    for chunk in (*chunks, points):
        path = directory / f"chunking-{chunk}.zarr"
        writer = FieldStoreWriter(
            path, overwrite=True, points=origin.points, normals=origin.normals,
            light_directions=np.resize(origin.light_directions, (grid, 3)), cameras=cameras,
            dtype="float16", sample_chunk=chunk,
        )  # fmt: skip
        start = time.perf_counter()
        for s in range(grid):
            for t in range(grid):
                writer.write_slab(s, t, slabs[(s + t) % 2][t % 2])
            writer.write_visibility(s, np.ones(points, dtype=bool))
        writer.finish()
        write = time.perf_counter() - start
        field = ReflectanceField.open(path, cached_slabs=0)
        camera = min(_timed(partial(field.camera_radiance, 1)) for _ in range(3))
        block = min(_timed(partial(field.sample_block, 65536, 131072)) for _ in range(3))
        slab_bytes = points * 3 * 2
        rows.append({
            "samples_per_chunk": chunk,
            "write_mb_s": grid * grid * slab_bytes / write / 1e6,
            "camera_read_mb_s": grid * slab_bytes / camera / 1e6,
            "sample_block_read_mb_s": grid * grid * 65536 * 6 / block / 1e6,
        })  # fmt: skip
        shutil.rmtree(path)
    shutil.rmtree(source)
    return rows


def _timed(call: Any) -> float:
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def measure_decode(directory: Path, width: int = 6000, height: int = 4000) -> float:
    """Seconds to decode one 24-megapixel 16-bit TIFF, best of three.

    :func:`processing.decode.decode_image`: the per-image cost of building a field from a
    capture, before its slabs are written.
    """
    import tifffile

    from processing.decode import decode_image

    path = directory / "decode-24mp.tif"
    rng = np.random.default_rng(0)
    ramp = np.linspace(0, 60000, width, dtype=np.float32)[None, :, None]
    pixels = (ramp + rng.normal(0, 200, (height, 1, 3))).clip(0, 65535).astype(np.uint16)
    tifffile.imwrite(path, np.broadcast_to(pixels, (height, width, 3)))
    best = min(_timed(lambda: decode_image(path)) for _ in range(3))
    path.unlink()
    return best


#: The capture issue 18 sizes: a 100 x 100 light-camera sweep of a 24-megapixel camera whose
#: object covers a third of the frame (8 million samples).
SWEEP = {"lights": 100, "cameras": 100, "samples": 8_000_000, "megapixels": 24}


def sweep_estimate(
    results: list[dict[str, Any]], decode_seconds: float, write_bytes_per_second: float | None
) -> list[dict[str, Any]]:
    """What each stage of :data:`SWEEP` costs one 2-core machine: measured costs x counts.

    Costs per sample are the slopes between the two largest sizes measured. Fitting scales
    with samples x observations (the kernel visits every (camera, light) of a sample),
    relighting through models with samples; building is one decode per image plus writing the
    float16 slabs, at the store's measured write rate (``--chunking``) or else the simulator's
    (which includes rendering: pessimistic).
    """
    observations = results[-1].get("grid", 30) ** 2
    sweep_obs = SWEEP["lights"] * SWEEP["cameras"]
    field_bytes = SWEEP["samples"] * sweep_obs * 3 * 2
    build = _seconds_per_sample(results, "build")
    write_rate = write_bytes_per_second or 1.0 / (build / (observations * 3 * 2))
    fit_rate = observations / _seconds_per_sample(results, "fit on cluster")  # sample-obs/s
    frame = SWEEP["samples"] * _seconds_per_sample(results, "relight")
    rows = [
        ("build: decode the images", sweep_obs * decode_seconds, sweep_obs, "images"),
        ("build: write the float16 store", field_bytes / write_rate, sweep_obs, "slabs"),
        ("fit (lambert, lambert+ggx)", SWEEP["samples"] * sweep_obs / fit_rate,
         -(-SWEEP["samples"] // 65536), "blocks of 65,536 samples"),
        ("relight: open the models, one frame; 50 environments", 50 * frame, 50,
         "environments"),
    ]  # fmt: skip
    return [
        {"stage": name, "one_machine_hours": seconds / 3600, "tasks": int(tasks), "task": task,
         "field_bytes": field_bytes}
        for name, seconds, tasks, task in rows
    ]  # fmt: skip


def _seconds_per_sample(results: list[dict[str, Any]], stage: str) -> float:
    """A stage's cost per sample (s).

    The slope between the two largest sizes (what one more sample costs, without the
    process's start-up); the largest size's mean when there is one size or the slope is not
    positive (noise at small sizes).
    """
    last = results[-1]
    mean = float(last["stages"][stage]["seconds"] / last["points"])
    if len(results) < 2:
        return mean
    before = results[-2]
    rise = last["stages"][stage]["seconds"] - before["stages"][stage]["seconds"]
    return float(rise / (last["points"] - before["points"])) if rise > 0 else mean


def _same_fit(a: Path, b: Path) -> bool:
    """Whether two saved fits hold the same arrays (every key, bit for bit)."""
    with np.load(a) as first, np.load(b) as second:
        return set(first.files) == set(second.files) and all(
            np.array_equal(first[key], second[key]) for key in first.files
        )


def measure_size(
    points: int, args: argparse.Namespace, fields: Path, rig: list[str]
) -> dict[str, Any]:
    """Every stage at one field size; returns its figures."""
    store = fields / f"{SCENE}-{points}.zarr"
    fit_in, fit_out = fields / f"{points}.process.npz", fields / f"{points}.dask.npz"
    grid = str(args.grid)
    stages: dict[str, dict[str, Any]] = {}
    stages["build"] = run_stage([*rig, "sim", "field", "--scene", SCENE, "--lights", grid,
                                 "--cameras", grid, "--points", str(points), "--dtype",
                                 "float16", "--overwrite", "-o", str(store)])  # fmt: skip
    stages["fit"] = run_stage([*rig, "fit", str(store), "--max-memory", args.max_memory,
                               "--quiet", "-o", str(fit_in)])  # fmt: skip
    cluster = run_stage([sys.executable, "-m", "bench.scale", "--stage", "cluster-fit",
                         "--store", str(store), "--workers", str(args.workers),
                         "--worker-memory", args.worker_memory_text,
                         "-o", str(fit_out)])  # fmt: skip
    report = json.loads(cluster["output"].strip().splitlines()[-1])
    # wait4 reports the largest of the process and its children (the workers): keep the
    # client's own peak, the workers' apart.
    cluster.update(report, identical=_same_fit(fit_in, fit_out))
    cluster["peak_bytes"] = report["client_peak_bytes"]
    stages["fit on cluster"] = cluster
    stages["relight"] = run_stage([*rig, "relight", str(store), "--env", args.env, "--scheme",
                                   "model", "--models", str(fit_in), "--view", VIEW, "--size",
                                   SIZE, "-o", str(fields / f"{points}.exr")])  # fmt: skip
    for stage in stages.values():
        stage["samples_per_second"] = points / stage["seconds"]
        stage.pop("output", None)
    field_bytes = points * args.grid * args.grid * 3 * 2
    disk = sum(f.stat().st_size for f in store.rglob("*") if f.is_file())
    if not args.keep:
        shutil.rmtree(store)
    return {"points": points, "grid": args.grid, "field_bytes": field_bytes,
            "store_disk_bytes": disk, "stages": stages}  # fmt: skip


def _table(results: list[dict[str, Any]]) -> str:
    lines = ["| samples | field (float16) | stage | time (s) | samples/s | peak memory |",
             "|---:|---:|---|---:|---:|---:|"]  # fmt: skip
    for row in results:
        for name, stage in row["stages"].items():
            peak = format_size(stage["peak_bytes"])
            if "worker_peak_bytes" in stage:
                workers = ", ".join(format_size(b) for b in stage["worker_peak_bytes"])
                peak += f" (workers {workers}; identical: {stage['identical']})"
            lines.append(
                f"| {row['points']:,} | {format_size(row['field_bytes'])} | {name} | "
                f"{stage['seconds']:.1f} | {stage['samples_per_second']:,.0f} | {peak} |"
            )
    return "\n".join(lines)


def _sweep_table(estimate: list[dict[str, Any]], machines: tuple[int, ...] = (1, 10, 100)) -> str:
    head = " | ".join(f"{n} machine{'s' if n > 1 else ''}" for n in machines)
    lines = [f"| stage | tasks | {head} |", "|---|---:|" + "---:|" * len(machines)]
    for row in estimate:
        # A stage cannot use more machines than it has tasks.
        hours = [row["one_machine_hours"] / min(n, row["tasks"]) for n in machines]
        cells = " | ".join(f"{h:.2f} h" if h >= 0.1 else f"{h * 60:.1f} min" for h in hours)
        lines.append(f"| {row['stage']} | {row['tasks']:,} {row['task']} | {cells} |")
    return "\n".join(lines)


def cost_and_memory_chart(
    path: Path,
    draw: Callable[[Axes, Axes], None],
    size_label: str,
    cost: tuple[str, str],
    memory: tuple[str, str],
) -> None:
    """A scale benchmark's chart: cost (left) and peak memory (right) against size, log-log.

    ``draw`` plots the lines on the two panels; ``cost`` and ``memory`` are each panel's
    y label and title. Shared with :mod:`bench.scale_rti`, so the two charts read alike.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (cost_axes, memory_axes) = plt.subplots(1, 2, figsize=(11, 4.2))
    draw(cost_axes, memory_axes)
    for axes, (ylabel, title) in ((cost_axes, cost), (memory_axes, memory)):
        axes.set(xscale="log", yscale="log", xlabel=size_label, ylabel=ylabel, title=title)
        axes.grid(True, which="both", alpha=0.3)
        axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _chart(results: list[dict[str, Any]], path: Path) -> None:
    sizes = [row["points"] for row in results]

    def draw(cost: Axes, memory: Axes) -> None:
        for name in results[0]["stages"]:
            cost.plot(sizes, [r["stages"][name]["seconds"] for r in results], "o-", label=name)
            peak = [r["stages"][name]["peak_bytes"] / 2**30 for r in results]
            memory.plot(sizes, peak, "o-", label=name)
        workers = [max(r["stages"]["fit on cluster"]["worker_peak_bytes"]) / 2**30 for r in results]
        memory.plot(sizes, workers, "s--", label="fit on cluster: largest worker")
        memory.plot(sizes, [r["field_bytes"] / 2**30 for r in results], "k:", label="the field")

    cost_and_memory_chart(
        path,
        draw,
        "samples",
        cost=("wall time (s)", "cost against size"),
        memory=("peak resident memory (GiB)", "peak memory per process against size"),
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m bench.scale``."""
    parser = argparse.ArgumentParser(prog="python -m bench.scale", description=__doc__)
    parser.add_argument("-o", "--output", type=Path, help="output directory")
    parser.add_argument("--sizes", default="250000,1000000,2000000", help="samples per field")
    parser.add_argument("--grid", type=int, default=30, help="lights = cameras (default 30)")
    parser.add_argument("--workers", type=int, default=2, help="local cluster workers")
    parser.add_argument("--worker-memory", dest="worker_memory_text", default="2G")
    parser.add_argument("--max-memory", default="700M", help="in-process fit budget")
    parser.add_argument("--env", default=None, help="panorama (default: the courtyard)")
    parser.add_argument("--keep", action="store_true", help="keep the fields")
    parser.add_argument(
        "--chunking", action="store_true", help="only measure the store's chunk sizes"
    )
    parser.add_argument(
        "--from-json", action="store_true",
        help="redraw the chart and the sweep estimate from DIR/scale.json of a finished run",
    )  # fmt: skip
    parser.add_argument("--stage", choices=("cluster-fit",), help=argparse.SUPPRESS)
    parser.add_argument("--store", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    args.worker_memory = parse_size(args.worker_memory_text)
    if args.stage == "cluster-fit":
        return _cluster_fit(args)
    if args.output is None:
        parser.error("-o DIR is required")
    if args.env is None:
        from core.sample_data import panorama_path

        args.env = str(panorama_path("courtyard"))
    out: Path = args.output
    fields = out / "fields"
    fields.mkdir(parents=True, exist_ok=True)
    if args.chunking:
        rows = measure_chunking(fields)
        (out / "chunking.json").write_text(json.dumps(rows, indent=2))
        print(json.dumps(rows, indent=2))
        return 0
    rig = [str(Path(sys.executable).with_name("rig"))]
    results: list[dict[str, Any]] = []
    if args.from_json:
        saved = json.loads((out / "scale.json").read_text())
        results = saved["sizes"] if isinstance(saved, dict) else saved
    for points in () if args.from_json else (int(n) for n in args.sizes.split(",")):
        print(f"{points:,} samples ...", file=sys.stderr, flush=True)
        results.append(measure_size(points, args, fields, rig))
        (out / "scale.json").write_text(json.dumps(results, indent=2))
    _chart(results, out / "scale.png")
    decode = measure_decode(fields)
    write_rate = None
    if (out / "chunking.json").is_file():
        from core.field_store import SAMPLE_CHUNK

        rows = json.loads((out / "chunking.json").read_text())
        write_rate = next(
            r["write_mb_s"] * 1e6 for r in rows if r["samples_per_chunk"] == SAMPLE_CHUNK
        )
    estimate = sweep_estimate(results, decode, write_rate)
    summary = {"sizes": results, "decode_24mp_seconds": decode, "sweep": estimate}
    (out / "scale.json").write_text(json.dumps(summary, indent=2))
    print(_table(results))
    print(_sweep_table(estimate))
    return 0


if __name__ == "__main__":
    sys.exit(main())
