from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

from app.cli import main


@pytest.mark.parametrize("name", ["courtyard.exr", "studio.exr"])
def test_sample_writes_lights_and_pictures(tmp_path: Path, courtyard_path: Path, name: str) -> None:
    panorama = courtyard_path.parent / name
    assert main(["sample", str(panorama), "-k", "32", "-o", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "lights.json").read_text())
    assert doc["k"] == 32 and doc["method"] == "tmed"
    assert doc["panorama"] == {"path": str(panorama), "width": 1024, "height": 512}
    assert np.array(doc["directions"]).shape == (32, 3)
    assert np.array(doc["rgb"]).shape == (32, 3)
    assert sum(doc["solid_angle_sr"]) == pytest.approx(4 * np.pi)
    for picture in ("overlay.png", "lights.png"):
        image = cv2.imread(str(tmp_path / picture))
        assert image is not None and image.shape == (512, 1024, 3)


def test_sample_controls(tmp_path: Path, courtyard_path: Path) -> None:
    modulation = tmp_path / "mask.png"
    mask = np.full((10, 20), 255, dtype=np.uint8)
    mask[5:] = 0  # no samples below the horizon
    cv2.imwrite(str(modulation), mask)
    args = [
        "sample",
        str(courtyard_path),
        "-k",
        "16",
        "--method",
        "median-cut",
        "--seed",
        "3",
        "--modulation",
        str(modulation),
        "--yaw",
        "30",
        "--exposure",
        "2",
        "-o",
        str(tmp_path / "o"),
    ]
    assert main(args) == 0
    doc = json.loads((tmp_path / "o" / "lights.json").read_text())
    assert np.all(np.array(doc["directions"])[:, 2] > 0)
    assert doc["controls"]["yaw_deg"] == 30 and doc["controls"]["exposure"] == 2


def test_errors_name_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "black.exr"
    from core.image_io import write_linear

    write_linear(bad, np.zeros((8, 16, 3), dtype=np.float32))
    assert main(["sample", str(bad), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "no light" in err


@pytest.fixture(scope="module")
def small_field(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("field") / "f.zarr"
    args = ["sim", "field", "--scene", "glossy-sphere", "--lights", "10", "--cameras", "6",
            "--points", "3000", "--size", "48x48", "-o", str(out)]  # fmt: skip
    assert main(args) == 0
    return out


@pytest.mark.parametrize("name", ["relit.exr", "relit.png", "turn.gif"])
def test_relight_writes_images_and_sequences(
    tmp_path: Path, small_field: Path, courtyard_path: Path, name: str
) -> None:
    args = ["relight", str(small_field), "--env", str(courtyard_path), "--view", "30,50",
            "--size", "48x48", "--frames", "3", "--sequence", "turntable", "-o",
            str(tmp_path / name)]  # fmt: skip
    assert main(args) == 0
    assert (tmp_path / name).stat().st_size > 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], "--view AZ,INCL is needed"),
        (["--view", "30,50", "-o", "x.bmp"], "x.bmp"),
        (["--view", "30,50", "--scheme", "mirror"], "invalid choice"),
    ],
)
def test_relight_refuses_bad_requests(
    tmp_path: Path,
    small_field: Path,
    courtyard_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    args = [
        "relight",
        str(small_field),
        "--env",
        str(courtyard_path),
        "-o",
        str(tmp_path / "a.png"),
    ]
    assert main(args + extra) == 2
    assert message in capsys.readouterr().err


def test_relight_an_rti_capture_folder(
    tmp_path: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rti = courtyard_path.parents[1] / "rti" / "loewenkopf"
    out = tmp_path / "lion.exr"
    # --fast: the quick rungs (the learned rung's training is tested on its own)
    assert main(["relight", str(rti), "--env", str(courtyard_path), "--fast", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "relighting mode:" in said and "light-stage" in said
    with OpenEXR.File(str(out), separate_channels=True) as exr:
        alpha = exr.channels()["A"].pixels
    assert alpha.shape == (43, 64) and alpha.min() == 1.0
    assert main(["relight", str(rti / "dirs.lp"), "--env", str(courtyard_path), "--view", "0,30",
                 "-o", str(out)]) == 2  # fmt: skip
    assert "one fixed view" in capsys.readouterr().err


def test_relight_through_vtk(tmp_path: Path, small_field: Path, courtyard_path: Path) -> None:
    out = tmp_path / "vtk.png"
    args = ["relight", str(small_field), "--env", str(courtyard_path), "--view", "30,50",
            "--size", "48x48", "--renderer", "pyvista", "-o", str(out)]  # fmt: skip
    assert main(args) == 0
    picture = cv2.imread(str(out))
    assert picture.shape == (48, 48, 3) and 0.2 < (picture.max(axis=2) > 0).mean() < 0.9


def test_relight_chooses_models_by_held_out_lights(
    tmp_path: Path, small_field: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["relight", str(small_field), "--env", str(courtyard_path), "--view", "30,50",
            "--size", "48x48"]  # fmt: skip
    saved = tmp_path / "fit.npz"
    assert main([*base, "--models", str(saved), "-o", str(tmp_path / "auto.png")]) == 0
    out = capsys.readouterr().out
    assert "relighting mode: model lambert+ggx predicts held-out lights" in out
    assert saved.exists()
    picked = ["--scheme", "model", "--model", "lambert", "-k", "16", "--models", str(saved)]
    assert main([*base, *picked, "-o", str(tmp_path / "lambert.exr")]) == 0
    with OpenEXR.File(str(tmp_path / "lambert.exr"), separate_channels=True) as exr:
        assert exr.channels()["A"].pixels.mean() > 0.2
    saved.write_bytes(b"garbage")
    assert main([*base, "--models", str(saved), "-o", str(tmp_path / "x.png")]) == 2
    assert "not a readable models file" in capsys.readouterr().err


def test_relight_warns_where_interpolation_fails(
    tmp_path: Path, small_field: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["relight", str(small_field), "--env", str(courtyard_path), "--size", "48x48",
            "-o", str(tmp_path / "x.png")]  # fmt: skip
    assert main([*base, "--view", "30,50"]) == 0  # fits and saves the models beside the field
    capsys.readouterr()
    assert main([*base, "--view", "30,50", "--scheme", "pixels"]) == 0
    assert "warning (ghosting)" in capsys.readouterr().out
    assert main([*base, "--view", "30,150", "--scheme", "pixels"]) == 0  # from below
    assert "warning (view-outside)" in capsys.readouterr().out


def test_relight_warns_of_a_sun_over_sparse_lights_and_of_grazing_views(
    tmp_path: Path, small_field: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from core.image_io import write_linear
    from sim.skies import procedural_sky

    sky = tmp_path / "sky.exr"
    write_linear(sky, procedural_sky(64, sun_share=0.9))
    base = ["relight", str(small_field), "--size", "48x48", "-o", str(tmp_path / "x.png")]
    assert main([*base, "--env", str(courtyard_path), "--view", "30,50"]) == 0  # saves a fit
    capsys.readouterr()
    # 10 lights and a glossy lobe: the sun's highlight ghosts (tests/render/test_stability.py).
    assert main([*base, "--env", str(sky), "--view", "30,50", "--scheme", "pixels"]) == 0
    out = capsys.readouterr().out
    assert "warning (sun-ghosting)" in out and "grazing" not in out
    assert main([*base, "--env", str(courtyard_path), "--view", "30,86", "--scheme",
                 "pixels"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "warning (grazing-view)" in out and "sun-ghosting" not in out
    assert main([*base, "--env", str(sky), "--view", "30,50", "--scheme", "model"]) == 0
    assert "sun-ghosting" not in capsys.readouterr().out  # the fitted lobe follows the sun


def test_an_existing_field_store_is_replaced_only_when_asked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "f.zarr"
    args = ["sim", "field", "--scene", "diffuse-sphere", "--lights", "4", "--cameras", "2",
            "--points", "300", "--size", "16x16", "-o", str(out)]  # fmt: skip
    assert main(args) == 0
    fit = out.with_name("f.zarr.models.npz")
    fit.write_bytes(b"a fit of the old data")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert str(out) in err and "--overwrite" in err and fit.exists()
    assert main([*args, "--overwrite"]) == 0
    assert not fit.exists()  # the old store's fit went with it
