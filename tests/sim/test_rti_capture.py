"""Simulated RTI captures on disk (sim.rti_capture): written as a dome would, imported back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.directions import hemisphere_layout
from core.errors import InputError
from processing.rti import import_rti
from sim.rti_capture import write_rti_capture


@pytest.mark.parametrize(("image_format", "depth", "tolerance"),
                         [("tiff16", "16-bit", 1e-4), ("jpeg", "8-bit", 0.03)])  # fmt: skip
def test_a_written_capture_imports_back_in_either_format(
    tmp_path: Path, image_format: str, depth: str, tolerance: float
) -> None:
    directions = hemisphere_layout(6, "fibonacci")
    ramp = np.linspace(0.05, 0.9, 16 * 12, dtype=np.float32).reshape(12, 16)
    images = np.stack([np.repeat(ramp[:, :, None] * (0.5 + 0.1 * t), 3, axis=2)
                       for t in range(6)])  # fmt: skip
    lp = write_rti_capture(tmp_path / "cap", "fit", images, directions, scale=1.0,
                           image_format=image_format)  # type: ignore[arg-type]  # fmt: skip
    field = import_rti(lp, tmp_path / "f.zarr")
    assert field.provenance["transfer"]["bit_depth"] == depth
    got = field.camera_slab(0).reshape(6, 12, 16, 3)
    np.testing.assert_allclose(got, np.clip(images, 0, 1), atol=tolerance)
    with pytest.raises(InputError, match="image format"):
        write_rti_capture(tmp_path / "x", "fit", images, directions, scale=1.0,
                          image_format="png")  # type: ignore[arg-type]  # fmt: skip


def test_the_mask_is_written_where_the_import_finds_it(tmp_path: Path) -> None:
    images = np.full((3, 6, 8, 3), 0.5, dtype=np.float32)
    mask = np.zeros((6, 8), dtype=bool)
    mask[1:5, 2:7] = True
    lp = write_rti_capture(tmp_path, "dome", images, hemisphere_layout(3, "fibonacci"),
                           scale=1.0, mask=mask)  # fmt: skip
    assert lp == tmp_path / "dome.lp" and (tmp_path / "dome.mask.png").is_file()
    field = import_rti(lp, tmp_path / "f.zarr")
    np.testing.assert_array_equal(field.visibility[0], mask.ravel())
    assert field.provenance["mask"]["found"] == "mask sidecar"
