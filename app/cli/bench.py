"""``rig bench``: the speed-against-accuracy benchmark of relighting, and the product's speed.

Application layer (like the rest of :mod:`app.cli`): it runs :mod:`bench.suite`, which writes
``DIR/results.json``, the charts and ``DIR/REPORT.md``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_bench_parser", "run_bench"]


def add_bench_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig bench`` on the ``rig`` sub-command parser.

    The options are :func:`bench.suite.add_arguments`' written out here: that module imports
    the whole suite (numpy, numba, OpenCV), seconds that every ``rig --help`` would pay.
    ``tests/app/cli/test_startup.py`` checks the two parsers offer the same options.
    """
    p = commands.add_parser(
        "bench",
        help="benchmark relighting speed against accuracy; write results.json and REPORT.md",
        description="Relight the simulator's scenes under HDR, LDR and procedural-sky "
        "environments with the paper's configuration and each change made to it, sweep K and "
        "the field density, time the capture, field building and the interactive loop, and "
        "write DIR/results.json, charts and DIR/REPORT.md. About 25 minutes on 2 cores the "
        "first time, 10 once its fields are cached; --quick takes about 3 minutes.",
    )
    p.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    p.add_argument(
        "--quick", action="store_true", help="a few minutes: one small field, fewer methods"
    )
    p.add_argument(
        "--fields",
        type=Path,
        default=None,
        help="directory named 'fields' where simulated fields are cached (default DIR/fields)",
    )
    p.set_defaults(handler=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``rig bench``; returns the exit status."""
    from bench.suite import run

    return run(args)
