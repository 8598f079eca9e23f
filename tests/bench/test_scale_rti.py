"""The RTI scale benchmark's capture generator and its watched stages (bench.scale_rti)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from bench.process_watch import run_watched
from bench.scale_rti import capture_size, make_rti_capture
from core.colour import srgb_to_linear
from core.errors import InputError
from core.image_io import read_pixels
from core.lp_format import read_lp
from core.sample_data import rti_capture_path
from processing.rti import import_rti


def test_sizes_are_three_by_two_in_jpeg_blocks() -> None:
    assert capture_size(24) == (6000, 4000)
    assert capture_size(6) == (3000, 2000)
    width, height = capture_size(1)
    assert (width, height) == (1224, 816) and width % 8 == height % 8 == 0
    with pytest.raises(InputError, match="megapixels must be positive"):
        capture_size(0)


def test_a_capture_is_the_bundled_one_upscaled_and_is_made_again_alike(tmp_path: Path) -> None:
    lp = make_rti_capture(tmp_path / "a", 0.02, lights=8)
    again = make_rti_capture(tmp_path / "b", 0.02, lights=8)
    width, height = capture_size(0.02)
    lights = read_lp(lp)
    bundled = read_lp(rti_capture_path())
    # Evenly spaced lights of the bundled capture, in its order and its directions.
    chosen = np.round(np.linspace(0, len(bundled) - 1, 8)).astype(int)
    np.testing.assert_allclose(lights.directions, bundled.directions[chosen], atol=1e-12)
    for name in lights.files:
        assert (lp.parent / name).read_bytes() == (again.parent / name).read_bytes()
    field = import_rti(lp, tmp_path / "a.zarr")
    assert field.shape == (1, 8, width * height) and field.image_shape == (height, width)
    assert field.dtype == np.float16  # 8-bit JPEGs
    # Each image, brought back to the bundled size, is the bundled image (the texture and
    # the noise average out): the same light falls on the same places.
    import cv2

    for t, index in enumerate(chosen):
        made = field.camera_slab(0)[t].reshape(height, width, 3)
        small = cv2.resize(made, (64, 43), interpolation=cv2.INTER_AREA)
        source = srgb_to_linear(
            read_pixels(rti_capture_path().parent / bundled.files[index]) / np.float32(255.0)
        )
        correlation = np.corrcoef(small.ravel(), source.ravel())[0, 1]
        assert correlation > 0.95, (t, correlation)
    # The texture makes the images more than a smooth upscale: neighbours differ.
    made = field.camera_slab(0)[0].reshape(height, width, 3)
    assert np.abs(np.diff(made, axis=1)).mean() > 0.002


def test_a_capture_needs_lights_the_bundled_one_has(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"lights must be 3\.\.240"):
        make_rti_capture(tmp_path, 0.01, lights=241)


def test_a_stage_above_the_memory_line_is_stopped_and_its_peak_kept(tmp_path: Path) -> None:
    # A child that takes 400 MB and then waits: stopped at 200 MB, its peak (wait4) above it.
    code = "import numpy, time; a = numpy.ones(50_000_000); time.sleep(120)"
    result = run_watched([sys.executable, "-c", code], stop_above=200 << 20, timeout=100.0)
    assert result["stopped"] == "memory"
    assert result["peak_bytes"] > 200 << 20
    assert result["returncode"] != 0


def test_a_server_is_stopped_once_it_says_it_is_ready(tmp_path: Path) -> None:
    code = "import time; print('serving on http://127.0.0.1:1', flush=True); time.sleep(120)"
    result = run_watched([sys.executable, "-c", code], stop_above=1 << 40, timeout=100.0,
                         ready="http://", linger=0.5)  # fmt: skip
    assert result["stopped"] == "ready" and result["ready_seconds"] is not None
    assert "serving on http://127.0.0.1:1" in result["output"]
    done = run_watched([sys.executable, "-c", "print('done')"], stop_above=1 << 40, timeout=100.0)
    assert done["stopped"] is None and done["returncode"] == 0 and done["output"] == "done\n"
