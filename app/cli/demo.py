"""``rig demo``: the demonstration pipeline (:mod:`app.demo`) and where its pictures go."""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli.args import output_directory


def add_demo(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig demo`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "demo",
        help="run the demonstration pipeline and write its pictures",
        description="Run the demonstration on the bundled panorama and write pictures and a "
        "report to the output directory.",
    )
    p.add_argument("-o", "--output", type=output_directory, default=Path("demo-out"),
                   help="output directory")  # fmt: skip
    p.add_argument("--quick", action="store_true", help="small fields (a smoke test)")
    p.set_defaults(handler=_run_demo)


def _run_demo(args: argparse.Namespace) -> int:
    from app.demo import run_demo

    report = run_demo(args.output, quick=args.quick)
    print(f"demo written to {args.output}/ (see {report})")
    return 0
