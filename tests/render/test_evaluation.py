from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import ReflectanceField
from render.evaluation import evaluate
from render.light_splits import ring_groups, split_lights
from sim.field import field_cameras, simulate_field

CAMERAS = field_cameras(3, width=32, height=32)


@pytest.fixture(scope="module")
def glossy(tmp_path_factory: pytest.TempPathFactory) -> tuple[ReflectanceField, ReflectanceField]:
    """A simulated glossy field and the same views under 6 other lights."""
    tmp = tmp_path_factory.mktemp("evaluation")
    simulate_field(tmp / "fit.zarr", "glossy-sphere", lights=30, cameras=CAMERAS, points=800,
                   layout="fibonacci")  # fmt: skip
    simulate_field(tmp / "test.zarr", "glossy-sphere", lights=hemisphere_layout(6, "grid"),
                   cameras=CAMERAS, points=800)  # fmt: skip
    return ReflectanceField.open(tmp / "fit.zarr"), ReflectanceField.open(tmp / "test.zarr")


def test_splits_hold_out_the_lights_they_say(glossy: tuple[ReflectanceField, ...]) -> None:
    field = glossy[0]
    fit, test = split_lights(field, "every-other")
    np.testing.assert_array_equal(test, np.arange(1, 30, 2))
    assert set(fit) | set(test) == set(range(30)) and not set(fit) & set(test)
    rings = ring_groups(field)
    fit, test = split_lights(field, "rings")
    assert set(rings[test]).isdisjoint(rings[fit])  # whole rings held out
    a, b = split_lights(field, "random:3"), split_lights(field, "random:3")
    np.testing.assert_array_equal(a[1], b[1])
    assert len(a[1]) == 15 and not np.array_equal(a[1], split_lights(field, "random:4")[1])
    with pytest.raises(InputError, match="unknown split 'halves'"):
        split_lights(field, "halves")
    with pytest.raises(InputError, match="random:SEED needs a whole number"):
        split_lights(field, "random:x")
    with pytest.raises(InputError, match="each side needs 3 or more"):
        split_lights(field.subset(lights=np.arange(4)), "every-other")


def test_rings_group_equal_inclinations(tmp_path: Path) -> None:
    azimuth = np.radians(np.arange(8) * 45.0 + 3.0)
    directions = [
        [np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)]
        for t in np.radians([60.0, 20.0, 40.4, 40.0]) for a in azimuth
    ]  # fmt: skip
    simulate_field(tmp_path / "rings.zarr", "diffuse-sphere", lights=np.array(directions),
                   cameras=CAMERAS[:1], points=200)  # fmt: skip
    rings = ring_groups(ReflectanceField.open(tmp_path / "rings.zarr"))
    # Numbered from the top; 40 and 40.4 degrees are one ring (within 2 degrees).
    np.testing.assert_array_equal(rings, np.repeat([2, 0, 1, 1], 8))


def test_the_measured_lights_themselves_score_perfectly(
    glossy: tuple[ReflectanceField, ...],
) -> None:
    field = glossy[0]
    result = evaluate(field, field, ["barycentric", "nearest"])
    for method in result.methods:
        assert method.mean is not None and method.mean.psnr == math.inf
        assert method.mean.rel_rmse < 1e-12 and method.mean.ssim == pytest.approx(1.0)
    assert len(result.methods[0].per_image) == 3 * 30


def test_held_out_lights_rank_the_methods(glossy: tuple[ReflectanceField, ...]) -> None:
    fit, test = glossy
    result = evaluate(fit, test, ["nearest", "barycentric", "rbf", "ptm", "lambert+ggx"])
    by_name = {m.name: m for m in result.methods}
    # The glossy sphere is exactly the lambert+ggx family: it must win, and nearest lose.
    assert result.best().name == "lambert+ggx"
    assert by_name["nearest"].mean is not None and by_name["barycentric"].mean is not None
    assert by_name["nearest"].mean.psnr < by_name["barycentric"].mean.psnr
    assert by_name["rbf"].note.startswith("sigma ")
    # A basis over light directions applies per camera to a field of points too.
    assert by_name["ptm"].mean is not None
    assert 0 < result.scale  # an HDR field: its test images' 99.5th percentile is white
    document = json.loads(json.dumps(result.to_json()))
    assert set(document["methods"]) == set(by_name)
    assert len(document["methods"]["rbf"]["per_image"]) == 3 * 6
    table = result.markdown()
    assert table.index("| lambert+ggx |") < table.index("| nearest |")


def test_a_method_that_cannot_apply_says_why(glossy: tuple[ReflectanceField, ...]) -> None:
    fit = glossy[0].subset(lights=np.arange(8))  # fewer lights than hsh3 has terms
    result = evaluate(fit, glossy[1], ["hsh3", "barycentric"])
    hsh = result.methods[0]
    assert hsh.mean is None and "not applicable" in hsh.note and "9 terms" in hsh.note
    assert result.best().name == "barycentric"


def test_a_test_of_other_views_is_refused(
    tmp_path: Path, glossy: tuple[ReflectanceField, ...]
) -> None:
    other = tmp_path / "other.zarr"
    simulate_field(other, "glossy-sphere", lights=6, cameras=field_cameras(2, width=32, height=32),
                   points=800)  # fmt: skip
    with pytest.raises(InputError, match="the test images must be of the same view"):
        evaluate(glossy[0], ReflectanceField.open(other), ["nearest"])
    with pytest.raises(InputError, match="a mask applies to a field of pixels"):
        evaluate(glossy[0], glossy[1], ["nearest"], mask=np.ones((32, 32), dtype=bool))


def test_a_local_cluster_scores_the_same(
    glossy: tuple[ReflectanceField, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from app.cli import main
    from core.cluster import dask_client

    fit, test = glossy
    split = fit.subset(lights=np.arange(0, 30, 2))  # a subset in memory goes along pickled
    methods = ["barycentric", "rbf", "hsh3", "lambert+ggx"]
    here = [evaluate(fit, test, methods), evaluate(split, test, methods)]
    with dask_client("local", workers=2, memory_limit=768 << 20, dashboard=False) as client:
        there = [evaluate(fit, test, methods, client=client),
                 evaluate(split, test, methods, client=client)]  # fmt: skip
    for a, b in zip(here, there, strict=True):
        assert [m.name for m in a.methods] == [m.name for m in b.methods] == methods
        assert a.scale == b.scale
        for m, n in zip(a.methods, b.methods, strict=True):
            assert (m.mean, m.per_image, m.note) == (n.mean, n.per_image, n.note)
    out = tmp_path / "scores.json"
    argv = ["evaluate", str(fit.path), "--split", "every-other", "--methods", "nearest,ptm",
            "--dask", "local", "--workers", "1", "--json", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "running on a local Dask cluster of 1 worker," in capsys.readouterr().err
    assert set(json.loads(out.read_text())["methods"]) == {"nearest", "ptm"}
