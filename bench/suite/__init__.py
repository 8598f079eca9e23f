"""The speed-against-accuracy benchmark: the paper's relighting and each change made to it.

Run: ``python -m bench.suite -o DIR [--quick] [--fields DIR]`` (``rig bench``). Writes
``DIR/results.json`` (every figure, and the machine), the charts and ``DIR/REPORT.md``
(:func:`bench.suite.report.write_report`, generated from the results alone). This package's
``__init__`` runs the studies in order and holds the command line; what is compared is in
:mod:`bench.suite.methods`, the fields and ground truths in :mod:`bench.suite.fields`, the
measuring in :mod:`bench.suite.measure`, the product's speed in :mod:`bench.suite.product`,
the layout of the results in :mod:`bench.suite.results` and the report (REPORT.md and the
charts) in :mod:`bench.suite.report`.

What is measured, for each scene of the simulator, reflectance field and relighting method:

- precompute: opening the engine (for per-sample models, loading their saved fit too; the fit
  itself is timed when this run makes it);
- time per new lighting (``set_lighting`` of a rotated panorama + ``render``) and per new view
  (``set_view`` of a turned camera + ``render``), medians after a warm-up frame;
- memory: the arrays the engine holds after a frame, beyond the opened field;
- error against the simulator's ground truth (relative RMSE, PSNR, SSIM) at a captured view
  and at a view halfway between two captured cameras, for every environment.

Studies: the ablation chain on an S = T = 30 field, a sweep of K, a sweep of field density, and
LDR against HDR panoramas; and the speed of the whole product on the simulated rig (capture
overhead, field building, the interactive loop). Fields are simulated into ``--fields`` once and
reused, and so are the ground truths (``DIR/truth``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from bench.advisor import simulator_error, validate_advisor
from bench.advisor_world import real_panoramas, validate_world_advisor, world_field
from bench.guard_advice import AdviceRecord
from bench.guard_advice import run as run_guard_advice
from bench.held_out import (
    HeldOutRecord,
    own_family_fields,
    run_held_out,
    world_fields,
    world_rti_captures,
)
from bench.stability import run_stability
from bench.suite.fields import (
    FieldRun,
    environment_record,
    environments,
    field_record,
    open_field,
)
from bench.suite.measure import MethodRows
from bench.suite.methods import (
    FULL,
    QUICK,
    SuiteConfig,
    ablation_methods,
    config_record,
    k_method,
)
from bench.suite.product import bench_product, interactive_record
from bench.suite.report import write_report
from bench.suite.results import (
    AdvisorRecord,
    FieldRecord,
    KRow,
    Machine,
    MachineRecord,
    Row,
    SuiteResults,
)
from core.atomic import output_problem
from core.errors import InputError
from core.field_store import ReflectanceField

__all__ = ["SuiteConfig", "add_arguments", "machine", "main", "run", "run_suite"]


def machine() -> Machine:
    """The machine and software the figures come from.

    Returns
    -------
    Machine: cores, load average, platform, processor, Python and the numeric libraries'
    versions
    """
    return {
        "cpu_count": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "opencv": cv2.__version__,
    }


def _max_rss_kib() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def run_suite(config: SuiteConfig, out: Path, fields_dir: Path | None = None) -> SuiteResults:
    """Run every study of ``config``; returns the results (as written to results.json).

    Parameters
    ----------
    config : SuiteConfig
    out : Path, the output directory (ground truths are cached in ``out/truth``)
    fields_dir : Path, optional, where fields are simulated once and reused (default
        ``out/fields``; a directory named ``fields`` is required by the naming of
        :func:`bench.sim_truth.field_path`)

    Returns
    -------
    SuiteResults

    Raises
    ------
    InputError
        When ``fields_dir`` is not named ``fields``.
    """
    started = time.perf_counter()
    fields_dir = fields_dir if fields_dir is not None else out / "fields"
    if fields_dir.name != "fields":
        raise InputError(f"the field cache must be a directory named 'fields', got {fields_dir}")
    envs = environments(config.environments, config.sky_height)
    at_start = machine()
    rss_start = _max_rss_kib()
    chain_methods = ablation_methods(config.quick_methods)
    by_label = {m.label.strip(): m for m in chain_methods}
    measured = MethodRows(envs, config.repeats)
    fields: list[FieldRecord] = []
    rows: list[Row] = []
    advisor: list[AdvisorRecord] = []
    chain_run: FieldRun | None = None
    for scene in config.scenes:
        run = open_field(fields_dir, out, scene, config.chain_field, envs)
        if scene == "glossy-sphere" or chain_run is None:
            chain_run = run
        fields.append(field_record(run))
        rows += [measured.row(run, "ablation", method) for method in chain_methods]
        for family in config.k_families:
            for k in config.k_values:
                row = measured.row(run, "k", k_method(family, k))
                k_row: KRow = {**row, "family": family}
                rows.append(k_row)
        opened = {config.chain_field: run}
        for spec in config.density_fields:
            dense = opened[spec] = open_field(fields_dir, out, scene, spec, envs)
            fields.append(field_record(dense))
            for label in config.density_methods:
                rows.append(measured.row(dense, "density", by_label[label]))
        if scene in config.advisor_scenes:
            for spec in config.advisor_fields:
                chosen = opened[spec]
                advisor += validate_advisor(
                    scene, chosen.field, chosen.models, chosen.views,
                    simulator_error(chosen.truths),
                    {name: envs[name].panorama for name in config.advisor_environments},
                    samples=config.advisor_samples,
                )  # fmt: skip
    product = bench_product(config, chain_run, fields_dir)
    stability = run_stability(out / "stability", config.quick_methods)
    held_out: list[HeldOutRecord] = []
    guard_advice: list[AdviceRecord] = []
    if config.held_out_methods:
        quick = config.name != "full"
        worlds = world_fields(fields_dir, config.held_out_worlds, config.world_field)
        domes = world_rti_captures(fields_dir, config.rti_worlds, config.rti_capture)
        held_out = run_held_out(
            fields_dir, quick=quick, worlds=worlds, rti_worlds=domes,
            methods=config.held_out_methods,
        )  # fmt: skip
        for world in config.advisor_worlds:
            store = world_field(fields_dir, world, config.advisor_world_field)
            advisor += validate_world_advisor(world, ReflectanceField.open(store),
                                              real_panoramas())  # fmt: skip
        guard_advice = run_guard_advice(
            out / "guard_advice", quick=quick, rti_worlds=domes, worlds=worlds,
            own_family=own_family_fields(fields_dir, quick=quick),
        )["records"]  # fmt: skip
    at_end: MachineRecord = {
        **at_start,
        "load_average_end": list(os.getloadavg()),
        "peak_rss_MB": _max_rss_kib() / 1024,
        "rss_growth_MB": (_max_rss_kib() - rss_start) / 1024,
    }
    return {
        "config": config_record(config),
        "machine": at_end,
        "chain_field": list(config.chain_field),
        "environments": {name: environment_record(env) for name, env in envs.items()},
        "chain": [m.label.strip() for m in chain_methods],
        "k_families": list(config.k_families),
        "density_methods": list(config.density_methods),
        "ssim": "mean SSIM map (OpenCV quality, 11x11 Gaussian) over covered pixels of the "
        "tone-mapped images: scaled so the truth's 99th percentile is white, clipped, 8-bit sRGB",
        "memory": "bytes of the numpy arrays the engine holds after a frame, beyond the opened "
        "field (the per-sample models' fits included)",
        "fields": fields,
        "rows": rows,
        "advisor": advisor,
        "product": product,
        "stability": stability,
        "held_out": held_out,
        "guard_advice": guard_advice,
        "interactive": interactive_record(product["loop"]) if "loop" in product else {},
        "wall_s": time.perf_counter() - started,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.suite [--quick] -o DIR [--fields DIR]``.

    Parameters
    ----------
    argv : list of str, optional, the arguments (default the command line's)

    Returns
    -------
    int, the exit status
    """
    parser = argparse.ArgumentParser(
        prog="bench.suite", description="Speed against accuracy of relighting, and the product"
    )
    add_arguments(parser)
    return run(parser.parse_args(argv))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The suite's options (shared by ``python -m bench.suite`` and ``rig bench``).

    Parameters
    ----------
    parser : argparse.ArgumentParser, gets ``-o/--output``, ``--quick`` and ``--fields``
    """
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument(
        "--quick", action="store_true", help="a few minutes: one small field, fewer methods"
    )
    parser.add_argument(
        "--fields",
        type=Path,
        default=None,
        help="directory named 'fields' where simulated fields are cached (default DIR/fields)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the suite for parsed arguments, write the results and the report.

    Parameters
    ----------
    args : argparse.Namespace, from a parser given :func:`add_arguments`

    Returns
    -------
    int, the exit status
    """
    out: Path = args.output
    for path in (out, args.fields):
        problem = None if path is None else output_problem(path, directory=True)
        if problem is not None:
            raise InputError(problem)
    out.mkdir(parents=True, exist_ok=True)
    config = QUICK if args.quick else FULL
    results = run_suite(config, out, args.fields)
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    report = write_report(results, out)
    print(f"wrote {out / 'results.json'} and {report} in {results['wall_s']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
