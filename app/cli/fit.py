"""``rig fit``: fit a field's per-sample models and save them beside it, at bounded memory.

Application layer: parses, opens the field and calls
:func:`processing.sample_models.fit_sample_models` in-process or on a Dask cluster
(:func:`core.cluster.dask_client`), then :func:`processing.sample_model_store.write_sample_models`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from app.cli.args import (
    add_dask_options,
    add_memory_option,
    cluster_for,
    names_among,
    output_file,
)
from app.cli.choices import MODELS

__all__ = ["add_fit"]


def add_fit(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig fit FIELD`` on the ``rig`` sub-command parser."""
    # Spelled out call by call, like every command's parser (duplicates pairs them by shape):
    # the options read here as --help prints them; those shared are app.cli.args' add_*.
    p = commands.add_parser(
        "fit",
        help="fit the per-sample models of a field store (bounded memory; --dask for a cluster)",
        description="Fit the per-sample models to every sample of a field store, block by "
        "block of samples (at most --max-memory of radiance at once), in this process or as "
        "Dask tasks (--dask), and save them beside the store (FIELD.models.npz, which rig "
        "relight and rig view then use) or at -o. The results are the same either way "
        "(docs/scale.md).",
    )
    p.add_argument("field", type=Path, help="field store")
    p.add_argument(
        "--models",
        type=lambda text: names_among(text, MODELS, "model"),
        help=f"comma-separated models among {', '.join(MODELS)} (default: by the field's kind)",
    )
    p.add_argument("-o", "--output", type=output_file, help="fit file (default FIELD.models.npz)")
    add_memory_option(p)
    add_dask_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_run_fit)


def _run_fit(args: argparse.Namespace) -> int:
    from core.field_store import ReflectanceField
    from core.memory_budget import format_size
    from processing.sample_model_store import default_models_path, fit_to_file
    from processing.sample_models import budget_for, sample_block_size

    field = ReflectanceField.open(args.field)
    target = args.output or default_models_path(field.path)
    started = time.perf_counter()
    with cluster_for(args) as client:
        budget = budget_for(args.max_memory, client)
        s, t, p = field.shape
        print(
            f"fitting {p} samples ({s} cameras x {t} lights) in blocks of "
            f"{sample_block_size(field, budget)} samples ({format_size(budget)} of radiance)",
            file=sys.stderr,
        )
        # Each block's fits go to the file as they come: a 24-megapixel capture's fits (13 GB
        # for the five models) are never held whole.
        fitted = fit_to_file(
            field, target, args.models, memory_bytes=budget, client=client,
        )  # fmt: skip
    elapsed = time.perf_counter() - started
    print(f"{', '.join(fitted.names)} fitted to {p} samples in {elapsed:.1f} s -> {target}")
    return 0
