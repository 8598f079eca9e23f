from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.turning import MODES, main
from core.directions import hemisphere_layout
from core.sample_data import PANORAMA_NAMES
from sim.rti_capture import write_rti_capture


def test_every_mode_is_timed_under_every_bundled_panorama(tmp_path: Path) -> None:
    directions = hemisphere_layout(25, "fibonacci")
    shading = 0.6 / np.pi * np.clip(directions[:, 2], 0.0, None)
    images = np.broadcast_to(shading[:, None, None, None], (25, 6, 8, 3))
    lp = write_rti_capture(tmp_path / "capture", "dome", images, directions, scale=1.0)
    assert main(["-o", str(tmp_path / "out"), "--repeats", "1", "--capture", str(lp)]) == 0
    rows = json.loads((tmp_path / "out" / "turning.json").read_text())["rows"]
    assert {(r["panorama"], r["mode"]) for r in rows} == {
        (p, label) for p in PANORAMA_NAMES for label, _ in MODES
    }
    assert all(r["new_yaw_ms"] > 0 for r in rows)
    assert (tmp_path / "out" / "turning.png").stat().st_size > 0


def test_a_capture_that_cannot_be_read_is_named_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = tmp_path / "none.lp"
    assert main(["-o", str(tmp_path / "out"), "--capture", str(missing)]) == 2
    said = capsys.readouterr().err
    assert str(missing) in said and "Traceback" not in said
