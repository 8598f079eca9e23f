"""The benchmark suite end to end on a tiny real configuration, and its report."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from app.cli_bench import add_bench_parser
from bench.report import CHARTS, pareto_front, write_report
from bench.suite import SuiteConfig, run_suite

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
)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    return run_suite(TINY, tmp_path_factory.mktemp("suite"))


def test_results_cover_every_study(results: dict[str, object]) -> None:
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


def test_report_from_results(results: dict[str, object], tmp_path: Path) -> None:
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
    assert "Pareto front" in text
    assert text.rstrip().endswith("A section from another module.")


def test_pareto_front() -> None:
    points = {"slow exact": (10.0, 0.01), "fast rough": (1.0, 0.2), "dominated": (5.0, 0.3)}
    assert pareto_front(points) == ["fast rough", "slow exact"]


def test_cli_parser() -> None:
    parser = argparse.ArgumentParser(prog="rig")
    add_bench_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "--quick", "-o", "out"])
    assert args.quick and args.output == Path("out") and callable(args.handler)
