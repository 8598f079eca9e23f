"""``rig sim field/render --renderer mitsuba``: path-traced worlds through the command line."""

from __future__ import annotations

from pathlib import Path

import OpenEXR
import pytest

from app.cli import main
from core.field_store import ReflectanceField
from core.sample_data import panorama_path


def test_a_path_traced_field_is_evaluated_on_held_out_lights(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    common = ["sim", "field", "--renderer", "mitsuba", "--scene", "copper-bowl", "--cameras",
              "2", "--points", "400", "--size", "32x32", "--spp", "16",
              "--layout", "fibonacci"]  # fmt: skip
    assert main([*common, "--lights", "12", "-o", str(tmp_path / "fit.zarr")]) == 0  # fmt: skip
    assert main([*common, "--lights", "4", "-o", str(tmp_path / "test.zarr")]) == 0
    field = ReflectanceField.open(tmp_path / "fit.zarr")
    assert field.shape == (2, 12, 400) and field.provenance["source"] == "mitsuba"
    argv = ["evaluate", str(tmp_path / "fit.zarr"), "--test", str(tmp_path / "test.zarr"),
            "--methods", "barycentric,adaptive", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "| adaptive |" in capsys.readouterr().out


def test_a_world_under_a_panorama(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "truth.exr"
    argv = ["sim", "render", "--renderer", "mitsuba", "--scene", "matte-relief", "--env",
            str(panorama_path("courtyard")), "--view", "0,40", "--size", "32x24", "--spp", "16",
            "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    with OpenEXR.File(str(out), separate_channels=True) as exr:
        channels = {k: v.pixels for k, v in exr.channels().items()}
    assert channels["A"].shape == (24, 32) and 0.05 < channels["A"].mean() < 0.95
    assert channels["R"].max() > 0
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[shape]\ntype = "teapot"\n[material]\ntype = "diffuse"\n')
    argv[argv.index("matte-relief")] = str(bad)
    assert main(argv) == 2
    assert "bad.toml" in capsys.readouterr().err


def test_an_rti_dome_of_a_world_is_evaluated_as_the_rti_literature_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "dome"
    argv = ["sim", "rti", "--scene", "matte-relief", "--lights", "12", "--test-lights", "4",
            "--size", "32x24", "--spp", "8", "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    assert (out / "fit.lp").read_text().startswith("12\nimages/fit_000.tif ")
    assert (out / "test.mask.png").is_file() and len(list((out / "images").iterdir())) == 16
    evaluate = ["evaluate", str(out / "fit.lp"), "--test", str(out / "test.lp"), "--quiet",
                "--methods", "rbf,adaptive", "--json", str(tmp_path / "e.json")]  # fmt: skip
    assert main(evaluate) == 0
    import json

    from processing.rti import open_field_or_rti

    with open_field_or_rti(out / "fit.lp") as fit:  # linear 16-bit TIFF, the mask beside
        assert fit.provenance["transfer"]["applied"] == "linear"
        assert 0.05 < fit.visibility.mean() < 0.95

    document = json.loads((tmp_path / "e.json").read_text())
    assert document["test_lights"] == 4 and document["methods"]["adaptive"]["mean"] is not None
    assert main(argv) == 2  # the folder is taken now
    assert "exists and is not empty" in capsys.readouterr().err
