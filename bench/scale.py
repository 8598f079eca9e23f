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
Not a test: nothing is asserted about time.
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
from pathlib import Path
from typing import Any

import numpy as np

from core.memory_budget import format_size, parse_size

__all__ = ["main", "run_stage"]

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
    return {"points": points, "field_bytes": field_bytes, "store_disk_bytes": disk,
            "stages": stages}  # fmt: skip


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


def _chart(results: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = [row["points"] for row in results]
    figure, (cost, memory) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name in results[0]["stages"]:
        cost.plot(sizes, [r["stages"][name]["seconds"] for r in results], "o-", label=name)
        peak = [r["stages"][name]["peak_bytes"] / 2**30 for r in results]
        memory.plot(sizes, peak, "o-", label=name)
    workers = [max(r["stages"]["fit on cluster"]["worker_peak_bytes"]) / 2**30 for r in results]
    memory.plot(sizes, workers, "s--", label="fit on cluster: largest worker")
    memory.plot(sizes, [r["field_bytes"] / 2**30 for r in results], "k:", label="the field")
    cost.set(xscale="log", yscale="log", xlabel="samples", ylabel="wall time (s)",
             title="cost against size")  # fmt: skip
    memory.set(xscale="log", yscale="log", xlabel="samples", ylabel="peak resident memory (GiB)",
               title="peak memory per process against size")  # fmt: skip
    for axes in (cost, memory):
        axes.grid(True, which="both", alpha=0.3)
        axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


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
    rig = [str(Path(sys.executable).with_name("rig"))]
    results = []
    for points in (int(n) for n in args.sizes.split(",")):
        print(f"{points:,} samples ...", file=sys.stderr, flush=True)
        results.append(measure_size(points, args, fields, rig))
        (out / "scale.json").write_text(json.dumps(results, indent=2))
    _chart(results, out / "scale.png")
    print(_table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
