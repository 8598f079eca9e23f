from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from bench.choice_study import main
from core.directions import hemisphere_layout
from render.rung_choice import SLOW_CANDIDATES
from sim.rti_capture import write_rti_capture


def _shiny_capture(folder: Path) -> Path:
    """Fit and test lights of one image: a matte half and a shiny half (a Phong lobe)."""

    def images(lights: np.ndarray) -> np.ndarray:
        cosine = np.clip(lights[:, 2], 0.0, None)
        toward = lights + np.array([0.0, 0.0, 1.0])
        lobe = 0.5 * (toward[:, 2] / np.linalg.norm(toward, axis=1)) ** 40 * cosine
        out = np.zeros((len(lights), 8, 12, 3))
        out[:, :, :6] = (0.5 / np.pi * cosine)[:, None, None, None]
        out[:, :, 6:] = (0.1 / np.pi * cosine + lobe)[:, None, None, None]
        return out

    fit = hemisphere_layout(30, "fibonacci")
    test = hemisphere_layout(12, "grid")
    test = test[test[:, 2] > 0.3]
    write_rti_capture(folder, "fit", images(fit), fit, scale=1.0)
    write_rti_capture(folder, "test", images(test), test, scale=1.0)
    return folder


def test_the_choice_study_puts_expected_beside_actual_for_every_rung(tmp_path: Path) -> None:
    capture = _shiny_capture(tmp_path / "shiny")
    main(["-o", str(tmp_path / "out"), "--capture", str(capture), "--no-lion", "--fast"])
    (result,) = json.loads((tmp_path / "out" / "choice_study.json").read_text())
    rungs = result["rungs"]
    assert result["capture"] == "shiny" and result["chosen"] in rungs
    assert {"rbf", "ptm-8bit", "hsh3-8bit", "barycentric", "adaptive"} <= set(rungs)
    assert not set(SLOW_CANDIDATES) & set(rungs)  # --fast
    assert all(math.isfinite(r["actual"]) for r in rungs.values())
    assert result["default"] == rungs[result["chosen"]]["actual"]
    assert result["best_baseline"] == max(rungs[b]["actual"] for b in ("rbf", "ptm-8bit",
                                                                      "hsh3-8bit"))  # fmt: skip
    # On this smooth object the choice's expectation ranks the chosen rung within a dB of
    # the best actual rung.
    assert result["default"] >= max(r["actual"] for r in rungs.values()) - 1.0
    assert (tmp_path / "out" / "choice_study.png").stat().st_size > 0
