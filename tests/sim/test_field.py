from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import zarr

from app.cli import main
from core.directions import hemisphere_layout
from core.errors import InputError
from sim.field import field_cameras, simulate_field
from sim.scenes import build_scene
from sim.synthetic_camera import DirectionalLight, render_under_light


@pytest.mark.parametrize("layout", ["grid", "fibonacci"])
@pytest.mark.parametrize("count", [1, 7, 20, 30, 400])
def test_hemisphere_layouts(layout: str, count: int) -> None:
    d = hemisphere_layout(count, layout)
    assert d.shape == (count, 3)
    assert np.all(d[:, 2] > 0)
    assert len(np.unique(d.round(9), axis=0)) == count


def test_layout_errors() -> None:
    with pytest.raises(InputError, match="at least one"):
        hemisphere_layout(0)
    with pytest.raises(InputError, match="unknown layout"):
        hemisphere_layout(4, "spiral")


def test_field_slabs_are_the_renderer_s_radiance(tmp_path: Path) -> None:
    cameras = field_cameras(4, width=96, height=96)
    simulate_field(tmp_path / "f.zarr", "textured-torus", lights=5, cameras=cameras, points=8000)
    store = zarr.open_group(str(tmp_path / "f.zarr"), mode="r")
    assert store["radiance"].shape == (4, 5, 8000, 3)
    assert store["radiance"].chunks == (1, 1, 8000, 3)  # one image, one slab (P < SAMPLE_CHUNK)
    assert store.attrs["schema_version"] == 1
    assert store.attrs["provenance"]["scene"]["name"] == "textured-torus"
    samples = build_scene("textured-torus", 8000)
    direction = store["light_directions"][3]
    image = render_under_light(samples, cameras[2], DirectionalLight(tuple(map(float, direction))))
    np.testing.assert_array_equal(store["radiance"][2, 3], image.point_radiance)
    np.testing.assert_array_equal(store["visibility"][2], image.visible)
    np.testing.assert_allclose(store["camera_directions"][2], cameras[2].direction)


def test_cli_field(tmp_path: Path) -> None:
    out = tmp_path / "field.zarr"
    args = [
        "sim",
        "field",
        "--scene",
        "diffuse-sphere",
        "--lights",
        "3",
        "--cameras",
        "2",
        "--layout",
        "fibonacci",
        "--points",
        "2000",
        "--size",
        "64x64",
        "--dtype",
        "float16",
        "-o",
        str(out),
    ]
    assert main(args) == 0
    store = zarr.open_group(str(out), mode="r")
    assert store["radiance"].dtype == np.float16 and store["radiance"].shape == (2, 3, 2000, 3)
    assert store["visibility"][:].any(axis=1).all()


def test_cli_field_refuses_bad_scene(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = [
        "sim",
        "field",
        "--scene",
        "cube",
        "--lights",
        "2",
        "--cameras",
        "2",
        "-o",
        str(tmp_path / "f.zarr"),
    ]
    assert main(args) == 2
    assert "unknown scene" in capsys.readouterr().err
