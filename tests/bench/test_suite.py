"""The benchmark suite end to end on a tiny real configuration, and its report."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import pytest

from app.cli.bench import add_bench_parser
from bench.suite import SuiteConfig, run_suite
from bench.suite.report import CHARTS, pareto_front, write_report
from bench.suite.results import (
    ConfigRecord,
    EnvironmentRecord,
    FieldRecord,
    KRow,
    MachineRecord,
    Row,
    Score,
    SuiteResults,
)

TINY = SuiteConfig(
    name="test",
    scenes=("glossy-sphere",),
    environments=("sky", "sky LDR"),
    chain_field=(6, 6, 600, 32),
    density_fields=((4, 4, 600, 32),),
    density_methods=("paper", "+ barycentric lights & views"),
    quick_methods=True,
    k_values=(4,),
    k_families=("paper", "sampled, barycentric"),
    repeats=1,
    capture=None,
    loop=False,
    sky_height=64,
    held_out_methods=("nearest", "rbf", "adaptive"),
)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> SuiteResults:
    return run_suite(TINY, tmp_path_factory.mktemp("suite"))


def test_results_cover_every_study(results: SuiteResults) -> None:
    rows = results["rows"]
    assert isinstance(rows, list)
    studies = {row["study"] for row in rows}
    assert studies == {"ablation", "k", "density"}
    for row in rows:
        assert {s["environment"] for s in row["scores"]} == {"sky", "sky LDR"}
        assert {s["view"] for s in row["scores"]} == {"captured", "between"}
        for score in row["scores"]:
            assert 0.0 <= score["relative_rmse"] < 10.0
            assert -1.0 <= score["ssim"] <= 1.0
    machine = results["machine"]
    assert isinstance(machine, dict) and machine["cpu_count"] >= 1
    json.dumps(results)  # results.json must hold everything as plain JSON


def test_report_from_results(results: SuiteResults, tmp_path: Path) -> None:
    # Through JSON, as the report is regenerated from results.json.
    loaded = json.loads(json.dumps(results))
    extra = "## Extra study\n\nA section from another module."
    path = write_report(loaded, tmp_path, extra_sections=[extra])
    text = path.read_text()
    for name in CHARTS:
        assert (tmp_path / name).stat().st_size > 0
        assert f"({name})" in text
    for heading in ("## The ablation chain", "## Error against K", "## LDR against HDR"):
        assert heading in text
    assert "| paper |" in text
    # The held-out study: the real capture, then the simulator labelled as its own family.
    assert "## Held-out lights" in text and (tmp_path / "held_out.png").stat().st_size > 0
    assert "### RTI lion (bundled): real, split every-other" in text
    assert "### glossy sphere (simulator): own family" in text
    assert [r["family"] for r in loaded["held_out"]] == ["real", "own family"]
    assert "Pareto front" in text
    assert text.rstrip().endswith("A section from another module.")


def _keys(record: Any) -> set[str]:
    return set(record.__required_keys__ | record.__optional_keys__)


def test_results_follow_their_typed_layout(results: SuiteResults) -> None:
    # The records are plain dicts at run time: the suite's output must be what the types say.
    assert set(results) == _keys(SuiteResults)
    assert set(results["machine"]) == _keys(MachineRecord)
    assert set(results["config"]) == _keys(ConfigRecord) == {f.name for f in fields(SuiteConfig)}
    # The record is the configuration as its dataclass would serialise it.
    assert json.dumps(results["config"]) == json.dumps(asdict(TINY))
    assert all(set(env) == _keys(EnvironmentRecord) for env in results["environments"].values())
    assert all(set(f) == _keys(FieldRecord) for f in results["fields"])
    for row in results["rows"]:
        assert set(row) == _keys(KRow if row["study"] == "k" else Row)
        assert all(set(score) == _keys(Score) for score in row["scores"])


def test_pareto_front() -> None:
    points = {"slow exact": (10.0, 0.01), "fast rough": (1.0, 0.2), "dominated": (5.0, 0.3)}
    assert pareto_front(points) == ["fast rough", "slow exact"]


def test_cli_parser() -> None:
    parser = argparse.ArgumentParser(prog="rig")
    add_bench_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "--quick", "-o", "out"])
    assert args.quick and args.output == Path("out") and callable(args.handler)


def test_world_fields_are_rendered_once(tmp_path: Path) -> None:
    from bench.held_out import WORLD_TEST_LIGHTS, world_fields
    from core.field_store import ReflectanceField

    spec = (2, 6, 24, 4, 300)
    ((name, fit, test),) = world_fields(tmp_path / "fields", ["matte-relief"], spec)
    assert name == "matte-relief"
    assert ReflectanceField.open(fit).shape == (2, 6, 300)
    assert ReflectanceField.open(test).shape == (2, WORLD_TEST_LIGHTS, 300)
    assert ReflectanceField.open(fit).provenance["source"] == "mitsuba"
    stamp = fit.stat().st_mtime_ns
    world_fields(tmp_path / "fields", ["matte-relief"], spec)  # cached: not rendered again
    assert fit.stat().st_mtime_ns == stamp
