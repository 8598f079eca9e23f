"""``render.web_export`` decoded by the documented format, independently of the writer.

The decoder here follows OpenLIME's ``ShaderRTI`` (``src/ShaderRTI.js``) and
``LayoutTiles.initDeepzoom`` (``src/LayoutTiles.js``) and reads the files with OpenCV and
OpenEXR directly: ``info.json``; ``plane_j.FORMAT`` holds planes 3j..3j+2 as R, G, B; a plane's
value is ``(byte / 255 - bias[p]) * scale[p]``; the colour is ``sum_j base_j(light) value[3j +
c]`` with the viewer's own PTM and HSH light weights (pi taken as 3.1415, HSH elevation held at
0.15 rad or more, as the viewer does).

The bound: each byte is the nearest of 256 levels ``scale[p] / 255`` apart, so a plane errs
by at most ``scale[p] / 510`` and the rendered channel c by at most
``sum_j |base_j(l)| scale[3j + c] / 510``; the viewer's pi of 3.1415 adds at most
``sum_j |value_j| |base_j(3.1415) - base_j(pi)|``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

from app.cli.export import add_export_web
from core.camera_model import PinholeCamera, camera_to_rig
from core.colour import linear_to_srgb
from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.lp_format import read_lp
from core.sample_data import rti_capture_path
from processing.rti import import_rti
from processing.sample_models import evaluate_basis
from render.light_prediction import make_predictor
from render.prediction_methods import bound_factor
from render.rti_fits import eight_bit_levels
from render.web_export import automatic_tile_size, openlime_display
from render.web_export.export import WebExport, export_web

#: Query lights in the camera frame (x right, y up, z toward the camera), all above the
#: viewer's HSH elevation floor of 0.15 rad; the last two between the measured ones.
QUERIES = np.array(
    [[0.0, 0.0, 1.0], [0.5, 0.3, 0.81], [-0.6, -0.4, 0.69], [0.2, -0.7, 0.68],
     [-0.3, 0.55, 0.78], [0.83, -0.1, 0.55]]
)  # fmt: skip
QUERIES = QUERIES / np.linalg.norm(QUERIES, axis=1, keepdims=True)

VIEWER_PI = 3.1415  # ShaderRTI's HSH.lightWeights
MIN_ELEVATION = 0.15  # ShaderRTI's HSH.minElevation


# --- the decoder (the documented format, nothing of render.web_export) --------------------


def _viewer_weights(kind: str, light: np.ndarray, pi: float = VIEWER_PI) -> np.ndarray:
    """ShaderRTI's ``PTM``/``HSH.lightWeights`` (one weight per term)."""
    x, y, z = (float(v) for v in light)
    if kind == "ptm":
        return np.array([1.0, x, y, x * x, x * y, y * y])
    phi = math.atan2(y, x)
    if phi < 0:
        phi = 2 * pi + phi
    theta = min(math.acos(z), pi / 2 - MIN_ELEVATION)
    cos_p, cos_t = math.cos(phi), math.cos(theta)
    cos_t2 = cos_t * cos_t
    root = math.sqrt(cos_t - cos_t2)
    return np.array([
        1.0 / math.sqrt(2 * pi),
        math.sqrt(6 / pi) * (cos_p * root),
        math.sqrt(3 / (2 * pi)) * (-1 + 2 * cos_t),
        math.sqrt(6 / pi) * (root * math.sin(phi)),
        math.sqrt(30 / pi) * (math.cos(2 * phi) * (-cos_t + cos_t2)),
        math.sqrt(30 / pi) * (cos_p * (-1 + 2 * cos_t) * root),
        math.sqrt(5 / (2 * pi)) * (1 - 6 * cos_t + 6 * cos_t2),
        math.sqrt(30 / pi) * ((-1 + 2 * cos_t) * root * math.sin(phi)),
        math.sqrt(30 / pi) * ((-cos_t + cos_t2) * math.sin(2 * phi)),
    ])  # fmt: skip


def _read_rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, path
    return np.ascontiguousarray(image[:, :, ::-1])


def _decode(folder: Path) -> tuple[dict, np.ndarray]:
    """``info.json`` and the plane values (H, W, nplanes), dequantised as the shader does."""
    info = json.loads((folder / "info.json").read_text())
    assert info["colorspace"] == "rgb"
    count = -(-info["nplanes"] // 3)  # ShaderRTI.init: njpegs
    stored = np.concatenate(
        [_read_rgb(folder / f"plane_{j}.{info['format']}") for j in range(count)], axis=2
    ).astype(np.float64)
    material = info["materials"][0]
    scale, bias = np.array(material["scale"]), np.array(material["bias"])
    return info, (stored / 255.0 - bias) * scale


def _render(info: dict, values: np.ndarray, light: np.ndarray, pi: float = VIEWER_PI):
    """ShaderRTI's ``RGB.render``: (H, W, 3), and the weights it used."""
    weights = _viewer_weights(info["type"], light, pi)[: info["nplanes"] // 3]
    terms = values.reshape(*values.shape[:2], -1, 3)  # plane 3 j + c: term j, channel c
    return np.einsum("j,hwjc->hwc", weights, terms), weights


# --- fixtures ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def lion(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    return import_rti(rti_capture_path(), tmp_path_factory.mktemp("lion") / "f.zarr")


@pytest.fixture(scope="module")
def lossless(lion: ReflectanceField, tmp_path_factory: pytest.TempPathFactory) -> WebExport:
    # Single PNG images (OpenLIME reads PNG only as tiles; the format is the same): the
    # decoder below reads them directly.
    out = tmp_path_factory.mktemp("png") / "web"
    return export_web(lion, out, models=("ptm", "hsh2", "hsh3"), image_format="png", tiles=False)


def _pixel_field(path: Path, values: np.ndarray, lights: np.ndarray, shape: tuple[int, int]):
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, shape[1], shape[0])
    writer = FieldStoreWriter(
        path, points=None, normals=None, light_directions=camera_to_rig(lights, camera),
        cameras=[camera], image_shape=shape,
    )  # fmt: skip
    for t, image in enumerate(values):
        writer.write_slab(0, t, image.astype(np.float32))
    writer.write_visibility(0, np.ones(shape[0] * shape[1], dtype=bool))
    writer.finish()
    return ReflectanceField.open(path)


# --- tests ---------------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["ptm", "hsh2", "hsh3"])
def test_the_decoded_export_relights_as_the_project_within_the_quantisation(
    lion: ReflectanceField, lossless: WebExport, model: str
) -> None:
    info, values = _decode(lossless.output / model)
    scale = np.array(info["materials"][0]["scale"])
    predictor = make_predictor(lion, f"{model}-8bit")
    predicted = predictor.predict(0, camera_to_rig(QUERIES, lion.cameras[0]))  # linear
    reference = linear_to_srgb(predicted)  # an RTI capture: 8-bit white is 1
    # Where the predictor's bound (1.25 x the brightest measured) clipped, it is not the model.
    limit = bound_factor(lion.light_directions) * lion.camera_slab(0).max(axis=0)
    kept = predicted < limit[None] * (1 - 1e-6)
    assert kept.mean() > 0.9
    worst = 0.0
    for q, light in enumerate(QUERIES):
        shown, weights = _render(info, values, light)
        exact_pi, _ = _render(info, values, light, pi=math.pi)
        per_channel = np.abs(weights) @ scale.reshape(-1, 3) / 510.0  # (3,)
        viewer_pi = np.abs(shown - exact_pi).reshape(-1, 3)
        bound = per_channel[None, :] + viewer_pi + 2e-5
        error = np.abs(np.clip(shown, 0, 1).reshape(-1, 3) - reference[q])
        assert (error[kept[q]] <= bound[kept[q]]).all(), (model, q)
        worst = max(worst, float((error[kept[q]] / bound[kept[q]]).max()))
    assert worst > 0.05  # the bound is a bound, not a wide margin


def test_info_json_holds_the_relight_fields(lion: ReflectanceField, lossless: WebExport) -> None:
    lp = read_lp(rti_capture_path())
    for written in lossless.models:
        info = json.loads((written.folder / "info.json").read_text())
        assert set(info) == {"width", "height", "format", "type", "colorspace", "lights",
                             "nplanes", "quality", "materials"}  # fmt: skip
        assert (info["width"], info["height"], info["format"]) == (64, 43, "png")
        terms = {"ptm": 6, "hsh2": 4, "hsh3": 9}[written.model]
        assert info["type"] == ("ptm" if written.model == "ptm" else "hsh")
        assert info["nplanes"] == written.planes == 3 * terms
        assert len(info["materials"][0]["scale"]) == len(info["materials"][0]["bias"]) == 3 * terms
        np.testing.assert_allclose(np.reshape(info["lights"], (-1, 3)), lp.directions, atol=1e-6)
        assert [p.name for p in written.files] == [f"plane_{j}.png" for j in range(terms)]
        assert written.rms_error < 0.5 and written.max_error < 2.0  # 8-bit levels


def test_the_viewer_bases_are_the_projects_reordered(lossless: WebExport) -> None:
    # Coefficients in the project's basis, converted as exported, render the same in the
    # viewer's basis (exact pi, no elevation floor reached).
    from render.web_export import viewer_coefficients

    rng = np.random.default_rng(3)
    for model, kind in (("ptm", "ptm"), ("hsh2", "hsh"), ("hsh3", "hsh")):
        ours = rng.normal(size=(5, evaluate_basis(model, QUERIES[:1]).shape[1], 3))
        theirs = viewer_coefficients(model, ours)  # type: ignore[arg-type]
        for light in QUERIES:
            expected = np.einsum("b,pbc->pc", evaluate_basis(model, light[None])[0], ours)
            weights = _viewer_weights(kind, light, math.pi)[: ours.shape[1]]
            np.testing.assert_allclose(np.einsum("b,pbc->pc", weights, theirs), expected,
                                       atol=1e-12, err_msg=model)  # fmt: skip


def test_jpeg_planes_stay_within_a_few_levels(lion: ReflectanceField, tmp_path: Path) -> None:
    result = export_web(lion, tmp_path / "web", models=("ptm", "hsh3"), quality=95)
    for written in result.models:
        assert [p.suffix for p in written.files] == [".jpg"] * (written.planes // 3)
        info, values = _decode(written.folder)
        assert info["format"] == "jpg" and info["quality"] == 95
        reference = linear_to_srgb(
            make_predictor(lion, f"{written.model}-8bit").predict(
                0, camera_to_rig(QUERIES, lion.cameras[0])
            )
        )
        shown = np.stack([np.clip(_render(info, values, light)[0], 0, 1) for light in QUERIES])
        rms = float(np.sqrt(np.mean((shown.reshape(reference.shape) - reference) ** 2))) * 255
        assert rms < 3.0, written.model  # measured 1.9 (ptm), 1.6 (hsh3) on this capture
        assert written.rms_error < 3.0


def test_deep_zoom_tiles_reassemble_into_the_planes(
    lion: ReflectanceField, lossless: WebExport, tmp_path: Path
) -> None:
    tiled = export_web(
        lion, tmp_path / "web", models=("ptm",), image_format="png", tiles=True, tile_size=16
    )
    folder = tiled.models[0].folder
    assert json.loads((folder / "info.json").read_text()) == json.loads(
        (lossless.output / "ptm" / "info.json").read_text()
    )
    for j in range(6):
        root = ElementTree.parse(folder / f"plane_{j}.dzi").getroot()
        assert root.tag == "{http://schemas.microsoft.com/deepzoom/2008}Image"
        suffix, side = root.get("Format"), int(root.get("TileSize", "0"))
        over = int(root.get("Overlap", "0"))
        size = root.find("{http://schemas.microsoft.com/deepzoom/2008}Size")
        assert size is not None
        width, height = int(size.get("Width", "0")), int(size.get("Height", "0"))
        # LayoutTiles.initDeepzoom: level 0 is the single top tile.
        levels = math.ceil(math.log2(max(width, height) / side)) + 1
        assert (suffix, side, over, width, height, levels) == ("png", 16, 1, 64, 43, 3)
        assembled = []
        for level in range(levels):
            w, h = width >> (levels - 1 - level), height >> (levels - 1 - level)
            cols, rows = -(-w // side), -(-h // side)
            names = {p.name for p in (folder / f"plane_{j}_files" / str(level)).iterdir()}
            assert names == {f"{c}_{r}.png" for c in range(cols) for r in range(rows)}
            picture = np.zeros((h, w, 3), np.uint8)
            for r in range(rows):
                for c in range(cols):
                    tile = _read_rgb(folder / f"plane_{j}_files" / str(level) / f"{c}_{r}.png")
                    x0, y0 = max(0, c * side - over), max(0, r * side - over)
                    x1, y1 = min(w, (c + 1) * side + over), min(h, (r + 1) * side + over)
                    assert tile.shape == (y1 - y0, x1 - x0, 3)
                    picture[y0:y1, x0:x1] = tile  # overlaps agree with their neighbours
                    np.testing.assert_array_equal(picture[y0:y1, x0:x1], tile)
            assembled.append(picture)
        whole = _read_rgb(lossless.output / "ptm" / f"plane_{j}.png")
        np.testing.assert_array_equal(assembled[-1], whole)
        for coarse, fine in itertools.pairwise(assembled):
            h, w = coarse.shape[:2]
            means = fine[: 2 * h, : 2 * w].astype(float).reshape(h, 2, w, 2, 3).mean(axis=(1, 3))
            assert np.abs(coarse - means).max() <= 0.5


def test_the_normal_map_round_trips(tmp_path: Path) -> None:
    # A Lambertian view: the left half tilted toward the image's right, the right half up.
    height, width = 6, 8
    normals = np.zeros((height, width, 3))
    normals[:, : width // 2] = (0.5, 0.0, math.sqrt(0.75))
    normals[:, width // 2 :] = (0.0, 0.4, math.sqrt(0.84))
    lights = hemisphere_layout(40, "fibonacci")
    lights = lights[lights[:, 2] > 0.75]  # every pixel lit by every light
    values = 0.6 * np.einsum("hwk,tk->thw", normals, lights)[..., None] * np.ones(3)
    field = _pixel_field(tmp_path / "f.zarr", values.reshape(len(lights), -1, 3), lights,
                         (height, width))  # fmt: skip
    result = export_web(field, tmp_path / "web", models=("ptm",), image_format="png")
    encoded = _read_rgb(result.normals_png)
    assert encoded.dtype == np.uint16 and encoded.shape == (height, width, 3)
    decoded = encoded / 65535.0 * 2.0 - 1.0
    np.testing.assert_allclose(decoded, normals, atol=1e-4)
    # Tilted toward the image's right: red above half; toward its top: green above half.
    assert (encoded[:, :4, 0] > 40000).all() and (encoded[:, 4:, 1] > 40000).all()
    with OpenEXR.File(str(result.normals_exr), separate_channels=True) as exr:
        channels = {name: np.asarray(c.pixels) for name, c in exr.channels().items()}
    exact = np.stack([channels[c] for c in "RGB"], axis=-1)
    np.testing.assert_allclose(exact, normals, atol=1e-5)
    np.testing.assert_array_equal(channels["A"], 1.0)
    np.testing.assert_allclose(decoded, exact, atol=1.0 / 65535.0)


def test_what_cannot_be_exported_is_refused(lion: ReflectanceField, tmp_path: Path) -> None:
    camera = PinholeCamera(0.0, 30.0, 10.0, 10.0, 8, 8)
    writer = FieldStoreWriter(
        tmp_path / "points.zarr", points=np.zeros((4, 3)), normals=np.tile([0, 0, 1.0], (4, 1)),
        light_directions=hemisphere_layout(6, "fibonacci"), cameras=[camera],
    )  # fmt: skip
    for t in range(6):
        writer.write_slab(0, t, np.ones((4, 3), np.float32))
    writer.write_visibility(0, np.ones(4, dtype=bool))
    writer.finish()
    points = ReflectanceField.open(tmp_path / "points.zarr")
    with pytest.raises(InputError, match=r"points\.zarr: a field of points"):
        export_web(points, tmp_path / "a")
    with pytest.raises(InputError, match=r"camera index 1 outside 0\.\.0"):
        export_web(lion, tmp_path / "b", camera=1)
    with pytest.raises(InputError, match="models rbf"):
        export_web(lion, tmp_path / "c", models=("rbf",))  # type: ignore[arg-type]
    with pytest.raises(InputError, match="tile size 64 must be smaller"):
        export_web(lion, tmp_path / "d", tiles=True, tile_size=64)
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="file: exists and is a file"):
        export_web(lion, tmp_path / "file")
    few = lion.subset(lights=np.arange(8))
    with pytest.raises(InputError, match="'hsh3' has 9 terms"):
        export_web(few, tmp_path / "e", models=("hsh3",))


def test_the_command_writes_an_rti_capture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = argparse.ArgumentParser(prog="rig")
    add_export_web(parser.add_subparsers(dest="command"))
    out = tmp_path / "web"
    args = parser.parse_args(["export-web", str(rti_capture_path().parent), "-o", str(out),
                              "--models", "hsh2", "--quiet"])  # fmt: skip
    assert args.handler(args) == 0
    said = capsys.readouterr().out
    assert "64x43 pixels of camera 0" in said and "12 planes (4 images)" in said
    assert (out / "hsh2" / "info.json").is_file() and (out / "hsh2" / "plane_3.jpg").is_file()
    assert (out / "normals.png").is_file() and (out / "normals.exr").is_file()
    with pytest.raises(SystemExit):
        parser.parse_args(["export-web", "x", "-o", str(out), "--models", "ptm,rbf"])
    assert "give distinct models among ptm, hsh2, hsh3" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parser.parse_args(["export-web", "x", "-o", str(out), "--quality", "0"])
    assert "JPEG quality must be 1..100" in capsys.readouterr().err


def test_png_planes_are_written_where_openlime_reads_them(
    lion: ReflectanceField, tmp_path: Path
) -> None:
    # OpenLIME's image layout asks for plane_N.jpg (Layout.imageUrl): PNG planes are tiled,
    # and the deep-zoom .dzi names their format (LayoutTiles.initDeepzoom).
    tiled = export_web(lion, tmp_path / "a", models=("ptm",), image_format="png")
    assert tiled.tile_size == 62 and tiled.models[0].levels == 2
    assert any("deep-zoom tiles" in note and "plane_N.jpg" in note for note in tiled.notes)
    assert any("tiles of 62 pixels" in note for note in tiled.notes)
    folder = tiled.models[0].folder
    assert [p.name for p in tiled.models[0].files] == [f"plane_{j}.dzi" for j in range(6)]
    assert not list(folder.glob("plane_*.png"))
    assert ElementTree.parse(folder / "plane_0.dzi").getroot().get("Format") == "png"
    assert (folder / "plane_0_files" / "1" / "1_0.png").is_file()
    assert json.loads((folder / "info.json").read_text())["format"] == "png"
    # Asked for single PNG images: written (a viewer of one's own reads them), and said.
    single = export_web(lion, tmp_path / "b", models=("ptm",), image_format="png", tiles=False)
    assert single.tile_size == 0 and (single.models[0].folder / "plane_0.png").is_file()
    assert any("cannot load them" in note for note in single.notes)
    # JPEG planes of a small image stay single images, with nothing to say.
    plain = export_web(lion, tmp_path / "c", models=("ptm",))
    assert plain.tile_size == 0 and plain.notes == ()


def test_the_tile_size_is_chosen_below_the_longest_side(lion: ReflectanceField, tmp_path: Path):
    assert automatic_tile_size(64, 43, 1) == 62  # 64 - 2: an inner tile is 64 wide
    assert automatic_tile_size(43, 64, 0) == 32
    assert automatic_tile_size(255, 10, 1) == 254  # longer than the default: the default
    assert automatic_tile_size(254, 10, 1) == 126
    assert automatic_tile_size(3, 1, 1) == 2
    with pytest.raises(InputError, match="2 x 2 pixels is too small"):
        automatic_tile_size(2, 2, 1)
    result = export_web(lion, tmp_path / "web", models=("ptm",), tiles=True)
    assert result.tile_size == 62 and result.models[0].levels == 2
    root = ElementTree.parse(result.models[0].folder / "plane_0.dzi").getroot()
    assert (root.get("Format"), root.get("TileSize")) == ("jpg", "62")


def test_bands_give_the_export_of_the_whole_view(
    lion: ReflectanceField, lossless: WebExport, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import render.web_export.export as module

    monkeypatch.setattr(module, "CHUNK_BYTES", 240 * 12 * 100)  # bands of 100 pixels
    assert module._band_size(lion, 0) == 100
    banded = export_web(
        lion, tmp_path / "web", models=("ptm", "hsh2", "hsh3"), image_format="png", tiles=False
    )
    for written, whole in zip(banded.models, lossless.models, strict=True):
        for a, b in zip(written.files, whole.files, strict=True):
            x, y = _read_rgb(a).astype(int), _read_rgb(b).astype(int)
            assert np.abs(x - y).max() <= 1 and (x == y).mean() > 0.999, a
    assert (
        np.abs(_read_rgb(banded.normals_png).astype(int) - _read_rgb(lossless.normals_png)).max()
        <= 1
    )


def test_the_view_is_read_a_band_at_a_time(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import render.web_export.export as module

    height, width = 30, 40
    lights = hemisphere_layout(14, "fibonacci")
    lights = lights[lights[:, 2] > 0.2]
    rng = np.random.default_rng(4)
    values = rng.uniform(0.05, 2.0, (len(lights), height * width, 3))
    field = _pixel_field(tmp_path / "f.zarr", values, lights, (height, width))
    band = 100
    monkeypatch.setattr(module, "CHUNK_BYTES", len(lights) * 12 * band)
    reads: list[int] = []
    original = ReflectanceField.camera_radiance

    def counted(self: ReflectanceField, camera: int, samples: slice = slice(None)):
        out = original(self, camera, samples)
        reads.append(out.shape[1])
        return out

    def whole(self: ReflectanceField, camera: int):
        raise AssertionError("the whole view was read")

    monkeypatch.setattr(ReflectanceField, "camera_radiance", counted)
    monkeypatch.setattr(ReflectanceField, "camera_slab", whole)
    result = export_web(field, tmp_path / "web", models=("ptm", "hsh2"))
    assert max(reads) == band
    # One pass for the display scale (a simulated field), one to fit: every pixel twice.
    assert sum(reads) == 2 * height * width
    assert result.scale > 0 and len(result.models) == 2


def test_openlime_display_blacks_out_the_shadows(lion: ReflectanceField) -> None:
    # Canvas.js: an 8-bit linear buffer (Shader.js srgb2linear = pow(c, 2.2)), then
    # pow(c, 1 / 2.2) to the canvas. Worked by hand: 14/255 -> 255 (14/255)^2.2 = 0.42 -> 0;
    # 15 -> 0.50 -> 1 -> 255 (1/255)^(1/2.2) = 20.5 -> 21; 25 -> 1.51 -> 2 -> 28.
    table = openlime_display(np.arange(256))
    assert table[14] == 0 and table[15] == 21 and table[24] == 21 and table[25] == 28
    assert table[0] == 0 and table[255] == 255 and (np.diff(table.astype(int)) >= 0).all()
    assert np.abs(table.astype(int) - np.arange(256)).max() <= 14
    # Its effect on the bundled capture's own images (docs/web-export.md states it).
    levels = eight_bit_levels(lion.camera_radiance(0)).astype(np.uint8)
    shown = openlime_display(levels)
    blacked = float(np.mean((shown == 0) & (levels > 0)))
    error = np.mean((shown.astype(float) - levels) ** 2)
    psnr = 10 * math.log10(255**2 / error)
    assert 0.21 < blacked < 0.23  # measured 0.218
    assert 38.8 < psnr < 39.3  # measured 39.0 dB


def test_the_level_table_is_eight_bit_levels(lion: ReflectanceField) -> None:
    from render.web_export.levels import _table, eight_bit

    # Every level boundary and its neighbours, every 7th float32 below 0.01 (where the
    # sRGB curve is steepest), random values in and out of 0..1, -0.0, and a capture.
    _, edges = _table()
    # The first float of each level 1..255, found apart from the table (bisection over the
    # float bits): a boundary may fall inside a bucket (the table's edge) or on its start.
    low_bits = np.zeros(255, dtype=np.int64)
    high_bits = np.full(255, int(np.float32(1.0).view(np.uint32)), dtype=np.int64)
    wanted = np.arange(1, 256, dtype=np.float32)
    while (high_bits - low_bits > 1).any():
        middle = (low_bits + high_bits) // 2
        up = eight_bit_levels(middle.astype(np.uint32).view(np.float32)) >= wanted
        high_bits, low_bits = np.where(up, middle, high_bits), np.where(up, low_bits, middle)
    boundaries = high_bits
    inside = edges[np.isfinite(edges)].view(np.uint32).astype(np.int64)
    assert set(inside) <= set(boundaries) and len(inside) >= 250
    near = (boundaries[:, None] + np.arange(-50, 50)).reshape(-1).astype(np.uint32)
    low = np.arange(0, np.float32(0.01).view(np.uint32), 7, dtype=np.uint32)
    rng = np.random.default_rng(8)
    tests = [
        near.view(np.float32),
        low.view(np.float32),
        rng.uniform(-0.2, 1.3, 2_000_000).astype(np.float32),
        np.array([-0.0, 0.0, 1.0, np.float32(1.0) + np.float32(1e-7), 5.0], np.float32),
        lion.camera_radiance(0),
    ]
    for values in tests:
        np.testing.assert_array_equal(eight_bit(values), eight_bit_levels(values))
    scaled = rng.uniform(0.0, 3.0, 100_000).astype(np.float32)
    np.testing.assert_array_equal(eight_bit(scaled, 0.37), eight_bit_levels(scaled, 0.37))
