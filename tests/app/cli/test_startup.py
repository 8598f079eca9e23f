"""``rig --help`` answers at once: building the parser imports none of the heavy libraries.

The help of every sub-command is printed in a fresh interpreter, which then lists what it
imported: numpy, numba, zarr and the library packages take seconds to import on a loaded
machine, so they belong in the handlers (``_run_*``), never at a module's top or in a
parser's registration. The check is structural, not timed (the time is a benchmark's:
``python -m bench.startup``). The names the parsers offer as choices come from
:mod:`app.cli.choices`, checked here against the modules that own them.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from app.cli import build_parser
from app.cli import choices as cli_choices

ROOT = Path(__file__).parents[3]

#: Third-party modules too slow to import for a help text.
HEAVY_LIBRARIES = (
    "numpy", "scipy", "numba", "torch", "cv2", "zarr", "aiohttp", "matplotlib", "dask",
    "imageio", "pyvista", "mitsuba",
)  # fmt: skip
#: The project's packages above core/: each imports numpy or zarr somewhere.
HEAVY_PACKAGES = ("rig", "capture", "processing", "render", "sim", "bench")

#: Run in a fresh interpreter: every sub-command's help, then what was imported.
EVERY_HELP = """
import argparse, contextlib, io, json, sys
from app.cli import build_parser, main
imported = sorted(sys.modules)

def commands(parser, prefix):
    yield prefix
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from commands(sub, [*prefix, name])

helps = {}
for argv in commands(build_parser(), []):
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        status = main([*argv, "--help"])
    helps[" ".join(argv)] = [status, printed.getvalue()]
print(json.dumps({"helps": helps, "imported": imported, "modules": sorted(sys.modules)}))
"""


def _children(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The sub-command parsers of ``parser``, by name."""
    children: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            children.update(action.choices)
    return children


def _subcommands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> set[str]:
    """Every sub-command under ``parser``, as typed after ``rig`` (``sim render``)."""
    found = set()
    for name, sub in _children(parser).items():
        found.add(" ".join((*prefix, name)))
        found |= _subcommands(sub, (*prefix, name))
    return found


def test_every_help_is_printed_without_importing_the_library() -> None:
    run = subprocess.run(
        [sys.executable, "-c", EVERY_HELP], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    helps = report["helps"]
    # Every sub-command was reached and printed its help (status 0, its usage line).
    assert set(helps) == {""} | _subcommands(build_parser())
    for command, (status, text) in helps.items():
        assert status == 0, command
        assert text.startswith(f"usage: rig {command}".rstrip()), command
    heavy = {*HEAVY_LIBRARIES, *HEAVY_PACKAGES}
    at_import = sorted({name.split(".")[0] for name in report["imported"]} & heavy)
    at_help = sorted({name.split(".")[0] for name in report["modules"]} & heavy)
    assert not at_help, (
        f"rig --help imported {', '.join(at_help)} ({', '.join(at_import) or 'none'} of them at "
        "the import of app.cli, the others while the parsers were built): import them in the "
        "command's handler (_run_*), and take choices from app.cli.choices"
    )


# A table of (choice, owner, name there), one row a choice: alike in shape to other tables.
@pytest.mark.parametrize(
    ("name", "owner", "attribute"),
    [
        ("SAMPLERS", "processing.sampling", "SAMPLERS"),
        ("INTERPOLATIONS", "processing.interpolation", "METHODS"),
        ("MODELS", "processing.sample_models", "MODELS"),
        ("PREDICTORS", "render.light_prediction", "PREDICTORS"),
        ("CHOSEN", "render.evaluation", "CHOSEN"),
        ("SCHEMES", "render.engines.interpolated", "SCHEMES"),
        ("SPLITS", "render.light_splits", "SPLITS"),
        ("SEQUENCES", "render.sequence", "SEQUENCES"),
        ("WEB_MODELS", "render.web_export", "WEB_MODELS"),
    ],
)
def test_the_choices_are_the_library_names(name: str, owner: str, attribute: str) -> None:
    import importlib

    assert getattr(cli_choices, name) == tuple(getattr(importlib.import_module(owner), attribute))


def test_the_web_exports_numbers_are_the_library_ones() -> None:
    from render import web_export

    assert cli_choices.WEB_TILE_SIZE == web_export.TILE_SIZE
    assert cli_choices.WEB_TILE_THRESHOLD == web_export.TILE_THRESHOLD
    assert cli_choices.WEB_NEURAL_SECONDS == web_export.NEURAL_SECONDS


def test_the_models_default_grid_is_the_library_one() -> None:
    from render.engines.modes import MOST_ACCURATE_MODELS

    assert cli_choices.MODEL_GRID_HEIGHT == MOST_ACCURATE_MODELS.grid_height


def _options(parser: argparse.ArgumentParser) -> list[tuple[object, ...]]:
    return [
        (a.option_strings, a.dest, a.type, a.default, a.required, a.help, type(a))
        for a in parser._actions
        if not isinstance(a, argparse._HelpAction)
    ]


def test_rig_bench_offers_the_suites_options() -> None:
    from app.cli.bench import add_bench_parser
    from bench.suite import add_arguments

    rig = argparse.ArgumentParser(prog="rig")
    add_bench_parser(rig.add_subparsers())
    (bench,) = (
        action.choices["bench"]
        for action in rig._actions
        if isinstance(action, argparse._SubParsersAction)
    )
    suite = argparse.ArgumentParser()
    add_arguments(suite)
    assert _options(bench) == _options(suite)


@pytest.mark.parametrize("command", [[], ["sim"]])
def test_the_startup_benchmark_finds_every_subcommand(
    command: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    from app.cli import main
    from bench.startup import subcommands

    assert main([*command, "--help"]) == 0
    listed = subcommands(capsys.readouterr().out)
    parser = build_parser()
    for name in command:
        parser = _children(parser)[name]
    expected = set(_children(parser))
    assert listed and set(listed) == expected
