"""core.sample_data: the bundled panoramas and the real RTI capture are there and readable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.colour import luminance
from core.directions import panorama_solid_angles
from core.errors import InputError
from core.image_io import read_pixels
from core.lp_format import read_lp
from core.sample_data import PANORAMA_NAMES, PanoramaName, panorama_path, rti_capture_path
from processing.panorama import read_panorama


def test_the_bundled_panoramas_are_named() -> None:
    assert PANORAMA_NAMES == ("courtyard", "studio")
    assert panorama_path() == panorama_path("courtyard")


@pytest.mark.parametrize("name", PANORAMA_NAMES)
def test_each_panorama_is_a_1024_by_512_hdr_file(name: PanoramaName) -> None:
    path = panorama_path(name)
    assert path.name == f"{name}.exr" and path.is_file()
    assert path.parent.name == "panoramas"
    panorama = read_panorama(path)
    assert (panorama.width, panorama.height) == (1024, 512)
    assert panorama.rgb.shape == (512, 1024, 3) and panorama.rgb.dtype == np.float32
    assert panorama.source == str(path)
    assert np.all(np.isfinite(panorama.rgb)) and panorama.rgb.min() >= 0.0
    assert panorama.rgb.max() > 1.0  # high dynamic range, not a display image


def test_the_studio_keeps_most_of_its_light_in_few_pixels() -> None:
    # The README: ~95 % of the studio's energy (luminance x solid angle) in 1 % of the pixels;
    # the courtyard's light is spread out (its maximum ~55).
    shares = {}
    for name in PANORAMA_NAMES:
        rgb = read_panorama(panorama_path(name)).rgb
        energy = (luminance(rgb) * panorama_solid_angles(*rgb.shape[:2])).ravel()
        shares[name] = np.sort(energy)[::-1][: energy.size // 100].sum() / energy.sum()
    assert shares["studio"] == pytest.approx(0.95, abs=0.01)
    assert shares["courtyard"] < 0.5


@pytest.mark.parametrize("name", ["", "Courtyard", "sky", "courtyard.exr"])
def test_an_unknown_panorama_is_refused_by_name(name: str) -> None:
    with pytest.raises(InputError, match=f"no bundled panorama {name!r}; use one of courtyard"):
        panorama_path(name)  # type: ignore[arg-type]


def test_the_rti_capture_lists_240_existing_images() -> None:
    lp = rti_capture_path()
    assert lp.name == "dirs.lp" and lp.is_file()
    assert (lp.parent / "LICENSE").is_file()
    lights = read_lp(lp)
    assert len(lights) == 240
    assert lights.directions.shape == (240, 3)
    np.testing.assert_allclose(np.linalg.norm(lights.directions, axis=1), 1.0, atol=1e-12)
    # The upper hemisphere toward the camera (z from 0.02 to 0.99, README).
    assert lights.directions[:, 2].min() > 0.0 and lights.directions[:, 2].max() < 1.0
    assert len(set(lights.files)) == 240
    for name in lights.files:
        assert (lp.parent / name).is_file(), name
    assert sorted(p.name for p in (lp.parent / "jpg").iterdir()) == sorted(
        Path(name).name for name in lights.files
    )


def test_the_rti_images_are_64_by_43_photographs() -> None:
    lp = rti_capture_path()
    files = read_lp(lp).files
    for name in (files[0], files[-1]):
        image = read_pixels(lp.parent / name)
        assert image.shape == (43, 64, 3) and image.dtype == np.uint8
        assert image.std() > 1.0  # a photograph, not a blank frame
