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


def test_the_progress_names_the_method_under_way(glossy: tuple[ReflectanceField, ...]) -> None:
    from core.progress import ProgressEvent, reporting_to

    seen: list[ProgressEvent] = []
    with reporting_to(seen.append):
        evaluate(glossy[0], glossy[1], ["nearest", "barycentric"])
    names = [event.what for event in seen]
    assert "evaluate: nearest" in names and "evaluate: barycentric" in names
    assert seen[-1].finished and seen[-1].done == 2 and seen[-1].total == 2


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


# --- a view too large to score whole: tiles of it ----------------------------------------


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An RTI capture of 96 x 64 pixels under 16 lights (a bumpy diffuse relief, 16-bit)."""
    from sim.rti_capture import write_rti_capture

    tmp = tmp_path_factory.mktemp("large-view")
    lights = hemisphere_layout(16, "fibonacci")
    y, x = np.mgrid[0:64, 0:96] / 8.0
    normals = np.stack([0.4 * np.sin(x), 0.4 * np.cos(1.3 * y), np.ones_like(x)], axis=2)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    albedo = 0.3 + 0.2 * np.sin(x[:, :, None] * np.array([1.0, 1.7, 2.3]))
    shading = np.clip(np.einsum("hwc,tc->thw", normals, lights), 0.0, None)
    return write_rti_capture(tmp, "relief", albedo[None] * shading[:, :, :, None], lights,
                             scale=1.0)  # fmt: skip


def test_a_large_view_is_sampled_by_tiles_spread_evenly() -> None:
    from render.held_out_lights import TILE_SIDE, pixel_sample

    assert pixel_sample((43, 64)) is None  # the bundled capture is scored whole
    assert pixel_sample(None) is None
    sample = pixel_sample((4000, 6000))
    assert sample is not None and sample.side == TILE_SIDE == 128 and sample.columns == 4
    # A 4 x 2 grid of 1500 x 2000 cells (the 3:2 view's aspect nearest), a tile at each centre.
    assert sample.origins == tuple((r, c) for r in (936, 2936) for c in (686, 2186, 3686, 5186))
    assert "8 tiles of 128 x 128 (a 4 x 2 grid" in sample.note()
    assert "131,072 of its 24,000,000" in sample.note()
    upright = pixel_sample((6000, 4000))
    assert upright is not None and upright.columns == 2 and len(upright.origins) == 8
    small = pixel_sample((64, 96), max_pixels=1024, side=16)
    assert small is not None and small.pixels == 1024 and len(small.origins) == 4
    mask = small.mask(None)
    # Half an SSIM window beside the seams is left out, the tiles' outer edges are not.
    assert mask.shape == (32, 32) and mask[0, 0] and mask[31, 31]
    assert not mask[:, 11:21].any() and not mask[11:21].any()


def test_tiles_score_what_the_whole_view_predicts_there(capture: Path, tmp_path: Path) -> None:
    from processing.image_quality import image_quality
    from processing.rti import import_rti
    from render.held_out_lights import held_out_split
    from render.light_prediction import make_predictor

    field = import_rti(capture, tmp_path / "relief.zarr")
    whole = held_out_split(field, "every-other")
    assert whole.sample is None and whole.fit.image_shape == (64, 96)
    pair = held_out_split(field, "every-other", max_pixels=1024, side=16)
    assert pair.sample is not None and pair.fit.image_shape == (32, 32)
    assert pair.test_lights is not None
    np.testing.assert_array_equal(pair.test_lights, np.arange(1, 16, 2))
    methods = ["nearest", "ptm", "lambert"]
    result = evaluate(pair.fit, pair.test, methods, mask=pair.mask, sample=pair.sample)
    assert "scored on 4 tiles of 16 x 16" in result.markdown()
    assert json.loads(json.dumps(result.to_json()))["pixels"]["side"] == 16
    # Every method predicts each pixel from its own values: the tiles' scores are those of the
    # whole view's predictions, cut into the same tiles.
    sample = pair.sample

    def tiled(images: np.ndarray) -> np.ndarray:  # (Q, 64, 96, 3) -> (Q, 32, 32, 3)
        out = np.zeros((len(images), 32, 32, 3), dtype=np.float32)
        for index, (row, column) in enumerate(sample.origins):
            y, x = index // 2 * 16, index % 2 * 16
            out[:, y : y + 16, x : x + 16] = images[:, row : row + 16, column : column + 16]
        return out

    truth = tiled(whole.test.camera_slab(0).reshape(-1, 64, 96, 3))
    counted = sample.mask(None) & pair.fit.visibility[0].reshape(32, 32)
    for method in result.methods:
        predicted = make_predictor(whole.fit, method.name).predict(0, whole.test.light_directions)
        expected = tiled(predicted.reshape(-1, 64, 96, 3))
        for got, image, reference in zip(method.per_image, expected, truth, strict=True):
            want = image_quality(image, reference, counted)
            assert got.psnr == pytest.approx(want.psnr, rel=1e-6, abs=1e-9), method.name
            assert got.ssim == pytest.approx(want.ssim, rel=1e-6), method.name
            assert got.rel_rmse == pytest.approx(want.rel_rmse, rel=1e-5, abs=1e-9), method.name


def test_rig_evaluate_says_it_scored_tiles(
    capture: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    import render.held_out_lights
    from app.cli import main

    monkeypatch.setattr(render.held_out_lights, "EVALUATE_PIXELS", 1024)
    monkeypatch.setattr(render.held_out_lights, "TILE_SIDE", 16)
    out = tmp_path / "scores.json"
    argv = ["evaluate", str(capture), "--test", str(capture), "--methods", "nearest",
            "--json", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "Large view, pixels: scored on 4 tiles of 16 x 16" in printed
    document = json.loads(out.read_text())
    # The measured lights themselves, on the tiles of both: exact.
    assert document["methods"]["nearest"]["mean"]["psnr"] is None or math.isinf(
        document["methods"]["nearest"]["mean"]["psnr"]
    )
    assert len(document["pixels"]["origins"]) == 4
