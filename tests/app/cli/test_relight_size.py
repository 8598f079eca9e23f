"""``--size`` on a field of pixels: the relit view is resampled to it and says so, or refused.

A field of pixels (an RTI capture) is relit at the pixels it was captured with; ``rig relight
--size`` used to be ignored for it, silently writing the capture's 64 x 43 when 640 x 430 was
asked. Now the relit image (a sequence's frames, ``--lights``' images) is resampled to the size
asked with a note, a size of other proportions is refused naming the ones that keep them, and
``rig batch`` (whose frames its tasks make) refuses a size other than the capture's.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from app.cli import main
from app.cli.args import resampled_size
from app.cli.evaluate import resample
from core.errors import InputError
from core.image_io import read_pixels

RTI = Path(__file__).parents[3] / "core" / "data" / "rti" / "loewenkopf"
#: The bundled capture's size (width, height).
NATIVE = (64, 43)


def _relight(tmp_path: Path, courtyard: Path, name: str, *extra: str) -> int:
    # nearest: relights without a fit, so the size is all these tests wait on.
    return main(["relight", str(RTI), "--env", str(courtyard), "--method", "nearest",
                 *extra, "-o", str(tmp_path / name)])  # fmt: skip


def test_relight_resamples_a_capture_to_the_size_asked(
    tmp_path: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _relight(tmp_path, courtyard_path, "native.exr") == 0
    assert "resampled" not in capsys.readouterr().out
    assert _relight(tmp_path, courtyard_path, "large.exr", "--size", "640x430") == 0
    said = capsys.readouterr().out
    assert "relit at the captured view's own size, 64x43 pixels, and resampled to 640x430" in said
    native = read_pixels(tmp_path / "native.exr")
    large = read_pixels(tmp_path / "large.exr")
    assert native.shape[:2] == (43, 64) and large.shape[:2] == (430, 640)
    # The relighting at the capture's pixels, enlarged: nothing else changed on the way.
    expected = cv2.resize(native, (640, 430), interpolation=cv2.INTER_LINEAR)
    np.testing.assert_allclose(large, expected, rtol=1e-6, atol=1e-7)
    assert _relight(tmp_path, courtyard_path, "small.png", "--size", "32x21") == 0
    assert read_pixels(tmp_path / "small.png").shape[:2] == (21, 32)


def test_relight_refuses_a_size_of_other_proportions(
    tmp_path: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _relight(tmp_path, courtyard_path, "square.png", "--size", "512x512") == 2
    err = capsys.readouterr().err
    assert "--size 512x512" in err and "64x43" in err and "512x344 or 762x512" in err
    assert not (tmp_path / "square.png").exists()


def test_relight_lights_resamples_too(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lp = tmp_path / "one.lp"
    lp.write_text("1\nlit.jpg 0.3 0.2 0.93\n")
    out = tmp_path / "lit"
    args = ["relight", str(RTI), "--lights", str(lp), "--method", "nearest", "--size", "128x86",
            "-o", str(out)]  # fmt: skip
    assert main(args) == 0
    assert "resampled to 128x86" in capsys.readouterr().out
    assert read_pixels(out / "lit.png").shape[:2] == (86, 128)


def test_batch_refuses_a_size_for_a_field_of_pixels(
    tmp_path: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from processing.rti import import_rti

    store = tmp_path / "lion.zarr"
    import_rti(RTI / "dirs.lp", store)
    args = ["batch", str(store), "--env", str(courtyard_path), "--sequence", "environment",
            "--size", "640x430", "-o", str(tmp_path / "out.zarr")]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "field of pixels" in err and "64x43" in err and "rig relight --size" in err
    assert not (tmp_path / "out.zarr").exists()


@pytest.mark.parametrize(
    ("requested", "expected"),
    [
        (None, None),  # not asked: the capture's own
        (NATIVE, None),  # its own
        ((640, 430), (640, 430)),  # 10 x
        ((100, 67), (100, 67)),  # 67.2 rounded: within a pixel
        ((67, 45), (67, 45)),  # 44.98 from the width
    ],
)
def test_resampled_size_keeps_the_proportions(
    requested: tuple[int, int] | None, expected: tuple[int, int] | None
) -> None:
    assert resampled_size(requested, NATIVE, "the capture") == expected


@pytest.mark.parametrize("requested", [(512, 512), (100, 70), (64, 45)])
def test_resampled_size_refuses_other_proportions(requested: tuple[int, int]) -> None:
    with pytest.raises(InputError, match="of other proportions"):
        resampled_size(requested, NATIVE, "the capture")


def test_resample_averages_when_it_shrinks_and_never_overshoots() -> None:
    checker = np.indices((8, 8)).sum(axis=0) % 2
    rgb = np.repeat(checker[..., None], 3, axis=2).astype(np.float32)
    np.testing.assert_allclose(resample(rgb, (4, 4)), 0.5)  # area: each 2 x 2 block's mean
    edge = np.zeros((4, 4, 3), np.float32)
    edge[:, 2:] = 10.0
    grown = resample(edge, (40, 40))
    assert grown.shape == (40, 40, 3) and grown.min() >= 0.0 and grown.max() <= 10.0
    coverage = np.zeros((4, 4), bool)
    coverage[:, 2:] = True
    mask = resample(coverage, (8, 8))
    assert mask.dtype == np.bool_ and mask[:, :4].sum() == 0 and mask[:, 4:].all()
    frame = (checker * 255).astype(np.uint8)[..., None].repeat(3, axis=2)
    assert resample(frame, (4, 4)).dtype == np.uint8
