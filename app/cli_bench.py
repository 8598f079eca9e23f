"""``rig bench``: the speed-against-accuracy benchmark of relighting, and the product's speed.

Application layer (like ``app/cli.py``): it runs :mod:`bench.suite`, which writes
``DIR/results.json``, the charts and ``DIR/REPORT.md``.
"""

from __future__ import annotations

import argparse

__all__ = ["add_bench_parser", "run_bench"]


def add_bench_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig bench`` on the ``rig`` sub-command parser."""
    from bench.suite import add_arguments

    p = commands.add_parser(
        "bench",
        help="benchmark relighting speed against accuracy; write results.json and REPORT.md",
        description="Relight the simulator's scenes under HDR, LDR and procedural-sky "
        "environments with the paper's configuration and each change made to it, sweep K and "
        "the field density, time the capture, field building and the interactive loop, and "
        "write DIR/results.json, charts and DIR/REPORT.md. About 25 minutes on 2 cores the "
        "first time, 10 once its fields are cached; --quick takes about 3 minutes.",
    )
    add_arguments(p)
    p.set_defaults(handler=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``rig bench``; returns the exit status."""
    from bench.suite import run

    return run(args)
