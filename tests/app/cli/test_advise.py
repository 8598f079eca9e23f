from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main


@pytest.fixture(scope="module")
def precapture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("precapture") / "f.zarr"
    args = ["sim", "field", "--scene", "glossy-sphere", "--lights", "10", "--cameras", "6",
            "--points", "1500", "--size", "48x48", "-o", str(out)]  # fmt: skip
    assert main(args) == 0
    return out


def test_advise_prints_and_saves_the_choice(
    tmp_path: Path, precapture: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    saved = tmp_path / "advice.json"
    args = ["advise", str(precapture), "--env", str(courtyard_path), "--samples", "400",
            "--tolerance", "0.1", "--json", str(saved)]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "choice: lambert+ggx" in out and "predicted by holding out" in out
    advice = json.loads(saved.read_text())
    assert advice["choice"].startswith("lambert+ggx") and len(advice["predictions"]) == 21


def test_plan_advise_suggests_a_density(
    tmp_path: Path, precapture: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["plan", "--advise", str(precapture), "--samples", "400", "--tolerance", "0.05"]
    assert main(base) == 2
    assert "needs --env" in capsys.readouterr().err
    assert main([*base, "--env", str(courtyard_path)]) == 0
    out = capsys.readouterr().out
    assert "suggested capture:" in out and "count =" in out
    assert main(["plan", "--config", str(tmp_path / "rig.toml")]) == 2
    assert "needs --config and --plan" in capsys.readouterr().err
