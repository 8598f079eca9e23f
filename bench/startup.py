"""The start-up benchmark: how long ``rig --help`` and each sub-command's help take, cold.

``python -m bench.startup -o DIR [--runs 5] [--rig PATH]`` runs ``rig --help``, then the help
of every sub-command ``rig --help`` lists (and theirs, ``rig sim render --help``), each
``--runs`` times as a fresh process, the way a person types them: the interpreter starts,
imports the command line and prints. For each it records the whole process's wall time (min,
median, max) and its peak resident memory (``wait4``), beside the bare interpreter's start
(``python -c pass``) for scale, and writes ``DIR/startup.json`` and prints the table.

The command line imports the library (numpy, numba, zarr: seconds) only in the handlers, so
a help is the interpreter and argparse; ``tests/app/cli/test_startup.py`` holds that import
structure, this measures what it buys. Not a test: nothing is asserted about time. On a
loaded machine the spread is wide: quote the median.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from core.atomic import write_json_atomic

__all__ = ["main", "measure", "subcommands"]

#: A sub-command's line in argparse's help: four spaces, its name, its help.
_LISTED = re.compile(r"^    (\S+)(?:\s{2,}|$)")


def measure(argv: list[str], runs: int) -> dict[str, Any]:
    """Run ``argv`` ``runs`` times; its wall seconds and peak memory, and what it printed.

    Raises RuntimeError with the output when it fails.
    """
    walls: list[float] = []
    peaks: list[int] = []
    output = ""
    for _ in range(runs):
        start = time.perf_counter()
        child = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
        )
        assert child.stdout is not None
        output = child.stdout.read().decode(errors="replace")
        _, status, usage = os.wait4(child.pid, 0)
        walls.append(time.perf_counter() - start)
        child.returncode = os.waitstatus_to_exitcode(status)
        if child.returncode != 0:
            raise RuntimeError(f"{' '.join(argv)} failed ({child.returncode}):\n{output[-2000:]}")
        peaks.append(usage.ru_maxrss * 1024)  # KiB on Linux
    return {
        "wall_s": {
            "min": min(walls),
            "median": statistics.median(walls),
            "max": max(walls),
        },
        "peak_mib": max(peaks) / 2**20,
        "output": output,
    }


def subcommands(help_text: str) -> list[str]:
    """The sub-commands a help lists (argparse's lines under the ``COMMAND`` metavar)."""
    names: list[str] = []
    listing = False
    for line in help_text.splitlines():
        if re.match(r"^  [A-Z_]+$", line):  # the metavar's line: COMMAND, SIM_COMMAND
            listing = True
            continue
        if listing:
            found = _LISTED.match(line)
            if found is None and not line.startswith("      "):  # not a wrapped help line
                listing = False
            elif found is not None:
                names.append(found.group(1))
    return names


def run(rig: list[str], runs: int) -> dict[str, Any]:
    """Time the bare interpreter, then ``rig --help`` and every sub-command's help."""
    bare = measure([sys.executable, "-c", "pass"], runs)
    rows: list[dict[str, Any]] = []
    pending: list[list[str]] = [[]]
    while pending:
        command = pending.pop(0)
        result = measure([*rig, *command, "--help"], runs)
        pending += [[*command, name] for name in subcommands(result.pop("output"))]
        rows.append({"command": " ".join(["rig", *command, "--help"]), **result})
    bare.pop("output")
    medians = [row["wall_s"]["median"] for row in rows]
    return {
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "cores": os.cpu_count(),
            "load_average": list(os.getloadavg()),
        },
        "date": time.strftime("%Y-%m-%d", time.gmtime()),
        "rig": rig,
        "runs": runs,
        "interpreter": {"command": "python -c pass", **bare},
        "commands": rows,
        "slowest_median_s": max(medians),
        "median_of_medians_s": statistics.median(medians),
    }


def table(results: dict[str, Any]) -> str:
    """The results as a plain-text table (medians, with min and max)."""
    lines = [f"{'command':<34} {'median s':>9} {'min s':>7} {'max s':>7} {'peak MiB':>9}"]
    for row in [results["interpreter"], *results["commands"]]:
        wall = row["wall_s"]
        lines.append(
            f"{row['command']:<34} {wall['median']:9.3f} {wall['min']:7.3f} {wall['max']:7.3f} "
            f"{row['peak_mib']:9.1f}"
        )
    lines.append(
        f"slowest median {results['slowest_median_s']:.3f} s over {len(results['commands'])} "
        f"helps, {results['runs']} runs each; load average at the start "
        f"{results['machine']['load_average'][0]:.2f} on {results['machine']['cores']} cores"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m bench.startup``."""
    parser = argparse.ArgumentParser(
        prog="python -m bench.startup",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument("--runs", type=int, default=5, help="runs of each command (default 5)")
    parser.add_argument(
        "--rig",
        help="the rig command to time (default: the rig script beside this interpreter, else "
        "python -m app.cli)",
    )
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    if args.rig is not None:
        rig = args.rig.split()
    else:
        script = Path(sys.executable).with_name("rig")
        rig = [str(script)] if script.exists() else [sys.executable, "-m", "app.cli"]
    results = run(rig, args.runs)
    args.output.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.output / "startup.json", results)
    print(table(results))
    print(f"-> {args.output / 'startup.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
