"""``rig evaluate`` and ``rig relight --lights`` on the bundled RTI capture."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from core.image_io import read_pixels
from core.lp_format import read_lp
from core.sample_data import rti_capture_path

RTI = rti_capture_path().parent


def _lp(path: Path, indices: range | list[int]) -> Path:
    """An .lp file of some of the bundled capture's images (absolute paths)."""
    lights = read_lp(RTI / "dirs.lp")
    lines = [str(len(indices))]
    for i in indices:
        x, y, z = lights.directions[i]
        lines.append(f"{(RTI / lights.files[i]).resolve()} {x} {y} {z}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_split_of_the_capture_is_scored_and_saved(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["evaluate", str(RTI), "--split", "every-other", "--quiet",
            "--methods", "nearest,barycentric,ptm-8bit",
            "--json", str(tmp_path / "e.json"), "--markdown", str(tmp_path / "e.md")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "| barycentric |" in out and "best: barycentric" in out
    document = json.loads((tmp_path / "e.json").read_text())
    assert document["test"] == "split every-other" and document["fit_lights"] == 120
    assert document["test_images"][:2] == ["light 1", "light 3"]
    assert document["display_scale"] == 1.0  # an RTI capture: its own 8-bit values
    nearest = document["methods"]["nearest"]["mean"]
    assert nearest["psnr"] < document["methods"]["barycentric"]["mean"]["psnr"]
    assert (tmp_path / "e.md").read_text().startswith("Held-out lights: 120 test lights")


def test_test_images_of_an_lp_file_and_a_mask(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fit = _lp(tmp_path / "fit.lp", range(0, 240, 2))
    test = _lp(tmp_path / "test.lp", range(1, 240, 8))
    mask = np.zeros((43, 64, 3), np.uint8)
    mask[10:30, 20:50] = 255
    from core.image_io import write_srgb8

    write_srgb8(tmp_path / "mask.png", mask)
    argv = ["evaluate", str(fit), "--test", str(test), "--methods", "barycentric", "--quiet",
            "--mask", str(tmp_path / "mask.png"), "--json", str(tmp_path / "e.json")]  # fmt: skip
    assert main(argv) == 0
    document = json.loads((tmp_path / "e.json").read_text())
    assert document["test_lights"] == 30
    assert document["test_images"][0].endswith("Loewenkopf_klein_0002.jpg")
    small = np.zeros((10, 10, 3), np.uint8)
    write_srgb8(tmp_path / "small.png", small + 255)
    argv[argv.index("--mask") + 1] = str(tmp_path / "small.png")
    assert main(argv) == 2
    assert "the mask is 10x10, the images are 64x43" in capsys.readouterr().err


def test_relight_under_the_lights_of_an_lp_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lights = tmp_path / "new.lp"
    lights.write_text("2\nup.png 0 0 1\nside/left.png -0.7 0.1 0.71\n")
    out = tmp_path / "out"
    argv = ["relight", str(RTI), "--lights", str(lights), "--method", "barycentric", "-o",
            str(out), "--exr"]  # fmt: skip
    assert main(argv) == 0
    up, left = read_pixels(out / "up.png"), read_pixels(out / "side" / "left.png")
    assert up.shape == (43, 64, 3) and (out / "side" / "left.exr").is_file()
    # Lit from the left, the left of the lion is brighter than its right (x is image right).
    assert left[:, :20].mean() > left[:, -20:].mean()
    assert abs(float(up[:, :20].mean()) - float(up[:, -20:].mean())) < abs(
        float(left[:, :20].mean()) - float(left[:, -20:].mean())
    )
    lights.write_text("1\n../escape.png 0 0 1\n")
    assert main(argv) == 2
    assert "would be written outside" in capsys.readouterr().err
    assert main([*argv, "--env", str(lights)]) == 2
    assert "give --env PANORAMA" in capsys.readouterr().err


def test_relight_chooses_the_rung_and_says_why(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fit = _lp(tmp_path / "fit.lp", range(0, 240, 4))
    directions = read_lp(RTI / "dirs.lp").directions[[1, 119]]
    test = tmp_path / "new.lp"
    test.write_text("2\n" + "".join(f"{n}.png {x} {y} {z}\n" for n, (x, y, z) in
                                     zip("ab", directions, strict=True)))  # fmt: skip
    assert (
        main(["relight", str(fit), "--lights", str(test), "--fast", "-o", str(tmp_path / "o")]) == 0
    )
    out = capsys.readouterr().out
    ranked = [
        line.split()[0] for line in out.splitlines() if line.startswith("  ") and " dB " in line
    ]
    method = next(line for line in out.splitlines() if line.startswith("method: "))
    if ranked[0] == "mixture" and "mixture" not in method:  # a tie keeps the single rung
        assert f"method: {ranked[1]} (best single rung: the mixture is not 0.2 dB better" in method
    else:
        assert method.startswith(
            f"method: {'a per-pixel' if ranked[0] == 'mixture' else ranked[0]}"
        )
        assert "(best held-out PSNR" in method
    assert len(list((tmp_path / "o").rglob("*.png"))) == 2
