"""Every bad input of the sweep (``tests/app/bad_inputs.py``) is a clear refusal.

No traceback, no hang, nothing accepted silently, nothing left behind: each case exits with
its status and a message naming the file or value (the README's promise).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from core.image_io import ImageFileError, read_linear, write_exr
from tests.app.bad_inputs import CASES, Case, Workspace, build_workspace, run_case
from tests.full_disk import ROOT, run_limited


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    return build_workspace(tmp_path_factory.mktemp("bad-inputs"))


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_a_bad_input_is_refused_clearly(case: Case, workspace: Workspace, tmp_path: Path) -> None:
    outcome = run_case(case, workspace, tmp_path / "case")
    assert outcome.kind == "clear", (
        f"{outcome.kind}: {outcome.detail}\nstdout: {outcome.out}\nstderr: {outcome.err}"
    )


def test_the_sweep_covers_every_sub_command() -> None:
    commands = {
        case.argv[0] if case.argv[0] != "sim" else " ".join(case.argv[:2]) for case in CASES
    }
    assert commands >= {
        "sample", "relight", "verify", "process", "capture", "plan", "advise", "evaluate",
        "export-lp", "calibrate", "doctor", "sim start", "sim field", "sim render",
        "sim photo", "sim rti", "bench", "demo",
    }  # fmt: skip
    assert len({case.name for case in CASES}) == len(CASES)


def test_a_truncated_exr_prints_only_the_tools_message(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    # The OpenEXR library writes its own lines to the process's stderr before raising.
    whole = tmp_path / "whole.exr"
    write_exr(whole, np.ones((64, 128, 3), np.float32))
    data = whole.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: len(data) * 3 // 4])
    with pytest.raises(ImageFileError, match=r"cut\.exr: cannot read as OpenEXR"):
        read_linear(cut)
    captured = capfd.readouterr()
    assert captured.err == "" and captured.out == ""


def test_a_torn_journal_is_reported_once_by_a_resume(
    workspace: Workspace, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:  # fmt: skip
    dataset = tmp_path / "dataset"
    shutil.copytree(workspace.dataset, dataset, ignore=shutil.ignore_patterns(".lock"))
    journal = dataset / "journal.jsonl"
    journal.write_bytes(journal.read_bytes()[:-30])  # a crash while writing the last line
    assert main(["verify", str(dataset)]) == 0
    assert "unfinished last line (a crash), ignored" in capsys.readouterr().out
    assert main(["capture", "--resume", str(dataset), "--quiet"]) == 0
    warnings = [r for r in caplog.records if "unfinished last line" in r.getMessage()]
    assert len(warnings) == 1 and "removed" in warnings[0].getMessage()
    assert main(["verify", str(dataset)]) == 0
    assert "unfinished" not in capsys.readouterr().out


# --- what only a process of its own can show: a full disk, a closed pipe, a FIFO ------------

#: The installed ``rig`` command beside this interpreter.
RIG = str(Path(sys.executable).with_name("rig"))


def test_a_full_disk_keeps_the_relit_image_already_there(
    workspace: Workspace, tmp_path: Path
) -> None:
    # Issue 28: on a full disk `rig relight ... -o r.png` printed "-> r.png", exited 0 and
    # left an empty r.png in place of the valid one (OpenCV's imwrite reports no failure).
    target = tmp_path / "r.png"
    argv = ["relight", str(workspace.field), "--env", str(workspace.panorama), "--view", "20,40",
            "--size", "48x48", "-o", str(target)]  # fmt: skip
    assert main(argv) == 0
    before = target.read_bytes()
    assert len(before) > 600
    done = run_limited([RIG, *argv], limit=600)
    assert done.returncode == 2, done.stderr
    assert f"rig relight: error: {target}: cannot write: the file is larger" in done.stderr
    assert "the earlier file is kept as it was" in done.stderr
    assert "Traceback" not in done.stderr and "->" not in done.stdout
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["r.png"]


@pytest.mark.parametrize("argv", [("sim", "scenes", "--json"), ("sim", "scenes")])
def test_output_into_a_closed_pipe_ends_quietly(argv: tuple[str, ...]) -> None:
    # `rig sim scenes --json | head -1` ended in a BrokenPipeError traceback.
    reading, writing = os.pipe()
    os.close(reading)  # the reader is gone before the first line
    try:
        done = subprocess.run(
            [RIG, *argv], stdout=writing, stderr=subprocess.PIPE, text=True, timeout=120,
            check=False,
        )  # fmt: skip
    finally:
        os.close(writing)
    assert (done.returncode, done.stderr) == (128 + signal.SIGPIPE, "")


def test_a_config_that_is_a_fifo_is_refused_not_waited_on(tmp_path: Path) -> None:
    # `--config` naming a FIFO blocked forever in open(): nothing writes into it here either.
    fifo = tmp_path / "rig.toml"
    os.mkfifo(fifo)
    done = subprocess.run(
        [RIG, "plan", "--config", str(fifo), "--plan", "docs/plan.example.toml"],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr == (
        f"rig plan: error: {fifo}: is a FIFO (named pipe), not a regular file; name a regular "
        "file\n"
    )
