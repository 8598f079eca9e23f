"""The command line draws the library's progress on stderr, unless ``--quiet``."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from app.cli import build_parser, main
from core.lp_format import read_lp
from core.sample_data import rti_capture_path

RTI = rti_capture_path().parent


def _small_lp(path: Path) -> Path:
    """An .lp file of 16 of the bundled capture's images (absolute paths)."""
    lights = read_lp(RTI / "dirs.lp")
    lines = ["16"]
    for i in range(0, 240, 15):
        x, y, z = lights.directions[i]
        lines.append(f"{(RTI / lights.files[i]).resolve()} {x} {y} {z}")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("quiet", [False, True])
def test_a_command_draws_its_bars_unless_quiet(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], quiet: bool
) -> None:
    argv = ["evaluate", str(_small_lp(tmp_path / "small.lp")), "--split", "every-other",
            "--methods", "nearest"] + (["--quiet"] if quiet else [])  # fmt: skip
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "| nearest |" in captured.out and "%|" not in captured.out  # bars go to stderr
    if quiet:
        assert "%|" not in captured.err and "rti:" not in captured.err
    else:
        # The import's bar (core.progress's events, drawn by tqdm), finished at 16/16.
        assert "rti: 100%" in captured.err and "16/16" in captured.err


def _commands(
    parser: argparse.ArgumentParser, words: tuple[str, ...] = ()
) -> list[tuple[str, ...]]:
    """Every runnable command's words and parser (``sim rti`` as ("sim", "rti"))."""
    nested = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not nested:
        return [words]
    return [found for action in nested for name, command in action.choices.items()
            for found in _commands(command, (*words, name))]  # fmt: skip


def test_every_command_takes_quiet(capsys: pytest.CaptureFixture[str]) -> None:
    commands = _commands(build_parser())
    assert ("relight",) in commands and ("sim", "rti") in commands
    for words in commands:
        assert main([*words, "--help"]) == 0
        assert "--quiet" in capsys.readouterr().out, words
