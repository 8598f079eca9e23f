"""The ``neural`` export read back by a transcription of OpenLIME's neural shader.

``_shader`` below transcribes cnr-isti-vclab/openlime ``src/ShaderNeural.js``
(``fragShaderSrc``: ``relightCoeff``, ``elu``, the uniforms) and ``src/LayerNeuralRTI.js``
(``initialize``: ``info.max``/``info.min`` flattened, ``info.weights[i]`` and
``info.biases[i]`` as the uniforms of layer i + 1, ``n = info.samples`` and ``c = info.planes
+ 2`` each rounded up to a multiple of 4; the constructor: the textures ``plane_1``,
``plane_2``, ``plane_3``, asked of the layout, which names them ``.jpg`` or ``.dzi``):
``color_k = texture_k * (max[k] - min[k]) + min[k]``; the input ``(color_1.rgb, color_2.rgb,
color_3.rgb, lights.xy, 0)``; ``output1[i] = elu(sum_j inputs[j] w1[c i + j] + b1[i])``, the
same for layer 2 (``n`` inputs), and ``output3[i] = sum_j output2[j] w3[n i + j] + b3[i]``;
the result is drawn through an 8-bit RGBA texture (clamped, rounded). Nothing of
``render.web_export`` is used to read the files.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.cli.export import add_export_web
from core.camera_model import rig_to_camera
from core.field_store import ReflectanceField
from core.sample_data import rti_capture_path
from processing.neural_rti_fit import NeuralSettings
from processing.rti import import_rti
from render.rti_fits import eight_bit_levels
from render.web_export.display import openlime_display
from render.web_export.export import WebExport, export_web

pytest.importorskip("torch", reason="the learned extra (PyTorch) is not installed")

#: Steps, not seconds, end these fits: a loaded machine gives the same model, later.
FIT = NeuralSettings(steps=2500, max_seconds=900.0, holdout=0.1, threads=1)


def _read_rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, path
    return np.ascontiguousarray(image[:, :, ::-1])


def _elu(a: np.ndarray) -> np.ndarray:
    return np.where(a > 0.0, a, np.exp(np.minimum(a, 0.0)) - 1.0)


def _codes(folder: Path, suffix: str = "jpg") -> tuple[dict, np.ndarray]:
    """``info.json`` and the dequantised codes (H, W, 9) the shader's ``relightCoeff`` reads."""
    info = json.loads((folder / "info.json").read_text())
    low = np.asarray(info["min"], dtype=np.float64).reshape(-1)  # info.min.flat(1)
    high = np.asarray(info["max"], dtype=np.float64).reshape(-1)
    textures = [_read_rgb(folder / f"plane_{k}.{suffix}") / 255.0 for k in (1, 2, 3)]
    colours = np.concatenate(textures, axis=2)
    return info, colours * (high - low) + low


def _shader(info: dict, codes: np.ndarray, light: np.ndarray) -> np.ndarray:
    """ShaderNeural's ``relightCoeff`` for every pixel (H, W, 9) under a light (x, y, ...)."""
    n = -(-info["samples"] // 4) * 4
    c = -(-(info["planes"] + 2) // 4) * 4
    h, w = codes.shape[:2]
    inputs = np.zeros((h * w, c))
    inputs[:, :9] = codes.reshape(-1, 9)
    inputs[:, 9:11] = light[:2]
    w1 = np.asarray(info["weights"][0]).reshape(n, c)  # layer1_weights[c/4 * i + j]
    w2 = np.asarray(info["weights"][1]).reshape(n, n)
    w3 = np.asarray(info["weights"][2]).reshape(3, n)
    b1, b2, b3 = (np.asarray(b, dtype=np.float64) for b in info["biases"])
    out1 = _elu(inputs @ w1.T + b1)
    out2 = _elu(out1 @ w2.T + b2)
    return (out2 @ w3.T + b3).reshape(h, w, 3)


def _texture(colour: np.ndarray) -> np.ndarray:
    """The 8-bit RGBA texture the layer relights into: clamped, rounded."""
    return np.rint(np.clip(colour, 0.0, 1.0) * 255.0)


def _psnr(shown: np.ndarray, reference: np.ndarray) -> float:
    return 10 * math.log10(255**2 / np.mean((shown - reference.astype(float)) ** 2))


@pytest.fixture(scope="module")
def lion(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    return import_rti(rti_capture_path(), tmp_path_factory.mktemp("lion") / "f.zarr")


@pytest.fixture(scope="module")
def captured(lion: ReflectanceField) -> np.ndarray:
    """The capture's 8-bit values (T, H, W, 3)."""
    h, w = lion.image_shape or (0, 0)
    return eight_bit_levels(lion.camera_radiance(0)).reshape(-1, h, w, 3)


@pytest.fixture(scope="module")
def lights(lion: ReflectanceField) -> np.ndarray:
    return rig_to_camera(lion.light_directions, lion.cameras[0])


@pytest.fixture(scope="module")
def jpeg(lion: ReflectanceField, tmp_path_factory: pytest.TempPathFactory) -> WebExport:
    out = tmp_path_factory.mktemp("neural") / "web"
    return export_web(lion, out, models=("neural",), neural=FIT)


def test_info_json_is_what_the_neural_layer_reads(jpeg: WebExport) -> None:
    written = jpeg.models[0]
    assert written.model == "neural" and written.planes == 9
    info = json.loads((written.folder / "info.json").read_text())
    assert set(info) == {"type", "format", "width", "height", "planes", "samples", "colorspace",
                         "min", "max", "weights", "biases"}  # fmt: skip
    assert (info["type"], info["format"], info["width"], info["height"]) == (
        "neural",
        "jpg",
        64,
        43,
    )
    assert (info["planes"], info["samples"], info["colorspace"]) == (9, 49, "rgb")
    assert np.shape(info["min"]) == np.shape(info["max"]) == (3, 3)
    n, c = 52, 12  # 49 and 11 rounded up to multiples of 4, as the layer does
    assert [len(w) for w in info["weights"]] == [n * c, n * n, 3 * n]
    assert [len(b) for b in info["biases"]] == [n, n, 3]
    w1 = np.reshape(info["weights"][0], (n, c))
    assert not w1[49:].any() and not w1[:, 11:].any() and w1[:49, :11].any()
    assert not np.reshape(info["weights"][1], (n, n))[:, 49:].any()
    assert not np.reshape(info["weights"][2], (3, n))[:, 49:].any()
    assert not np.asarray(info["biases"][0])[49:].any()
    assert [p.name for p in written.files] == ["plane_1.jpg", "plane_2.jpg", "plane_3.jpg"]
    assert not list(written.folder.glob("plane_0*"))  # the layer asks for 1, 2, 3


def test_the_shader_renders_the_model_as_written(jpeg: WebExport, lights: np.ndarray) -> None:
    # The transcription, reading the files, gives what the written model (the decoder as
    # tuned to the stored codes) predicts from the codes as stored: the packing is right.
    network = jpeg.models[0].network
    assert network is not None
    info, codes = _codes(jpeg.models[0].folder)
    for t in (0, 37, 120, 211):
        expected = network.decode(codes.reshape(-1, 9), lights[t : t + 1])[0]
        np.testing.assert_allclose(
            _shader(info, codes, lights[t]).reshape(-1, 3), expected, atol=2e-5
        )


def test_the_export_renders_the_capture_at_held_out_lights(
    jpeg: WebExport, lights: np.ndarray, captured: np.ndarray
) -> None:
    written = jpeg.models[0]
    network = written.network
    assert network is not None and len(network.held) == 24  # a tenth of the 240 lights
    info, codes = _codes(written.folder)
    shown = np.stack([_texture(_shader(info, codes, lights[t])) for t in range(len(lights))])
    held = _psnr(shown[network.held], captured[network.held])
    trained = _psnr(shown[network.trained], captured[network.trained])
    assert held > 25.0  # measured 26.7 dB
    assert trained > 26.0  # measured 27.6 dB
    # What the command reports is this measure (on every pixel: there are fewer than 4096).
    assert written.held_psnr is not None and written.fit_held_psnr is not None
    assert abs(written.held_psnr - held) < 0.01 and abs(written.psnr - trained) < 0.01
    # The quantisation and JPEG cost little once the decoder is tuned to the stored codes.
    assert written.fit_psnr is not None and written.psnr > written.fit_psnr - 0.5
    assert written.held_psnr > written.fit_held_psnr - 0.5


def test_the_stored_codes_are_within_quantisation_of_the_fitted(
    lion: ReflectanceField, lights: np.ndarray, tmp_path: Path
) -> None:
    # PNG planes (lossless): the shader's colour from the stored codes is the written
    # decoder's colour from the fitted codes, up to the codes' quantisation (half a step,
    # (max - min) / 510, per value), carried to first order by the decoder's derivatives.
    settings = dataclasses.replace(FIT, steps=600, holdout=0.0)
    result = export_web(
        lion, tmp_path / "web", models=("neural",), image_format="png", tiles=False,
        neural=settings,
    )  # fmt: skip
    network = result.models[0].network
    assert network is not None and network.codes is not None
    info, stored = _codes(result.models[0].folder, "png")
    step = (np.asarray(info["max"]) - np.asarray(info["min"])).reshape(-1) / 510.0
    fitted = network.codes.astype(np.float64)
    assert (np.abs(stored.reshape(-1, 9) - fitted).max(axis=0) <= step * (1 + 1e-5) + 1e-7).all()
    worst = 0.0
    for t in range(0, len(lights), 10):
        light = lights[t : t + 1]
        exact = network.decode(fitted, light)[0].astype(np.float64)
        bound = np.zeros_like(exact)
        for k in range(9):
            moved = fitted.copy()
            moved[:, k] += 1e-2
            slope = (network.decode(moved, light)[0] - exact) / 1e-2
            bound += np.abs(slope) * step[k]
        error = np.abs(_shader(info, stored, lights[t]).reshape(-1, 3) - exact)
        assert (error <= 1.5 * bound + 5e-5).all(), t
        worst = max(worst, float((error / (bound + 1e-9)).max()))
    assert worst > 0.2  # the bound is not a wide margin


def test_deep_zoom_planes_are_named_as_the_layer_asks(
    lion: ReflectanceField, tmp_path: Path
) -> None:
    settings = dataclasses.replace(FIT, steps=5, holdout=0.0)
    result = export_web(lion, tmp_path / "web", models=("neural",), tiles=True, neural=settings)
    folder = result.models[0].folder
    assert [p.name for p in result.models[0].files] == [f"plane_{k}.dzi" for k in (1, 2, 3)]
    for k in (1, 2, 3):
        root = ElementTree.parse(folder / f"plane_{k}.dzi").getroot()
        assert (root.get("Format"), root.get("TileSize")) == ("jpg", "62")
        assert (folder / f"plane_{k}_files" / "1" / "1_0.jpg").is_file()
    assert not list(folder.glob("plane_0*"))


def test_a_large_view_is_coded_by_an_encoder(
    lion: ReflectanceField,
    lights: np.ndarray,
    captured: np.ndarray,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # As on a capture of more pixels than get codes of their own: an encoder is fitted on a
    # sample of the pixels and codes every pixel, the others included, in a second pass.
    import render.web_export.export as module

    monkeypatch.setattr(module, "FREE_CODE_PIXELS", 1000)
    monkeypatch.setattr(module, "NEURAL_SAMPLES", 1200)
    settings = dataclasses.replace(FIT, steps=1500, holdout=0.0)
    result = export_web(lion, tmp_path / "web", models=("neural",), neural=settings)
    network = result.models[0].network
    assert network is not None and network.codes is None and len(network.encoder) == 4
    info, codes = _codes(result.models[0].folder)
    shown = np.stack([_texture(_shader(info, codes, lights[t])) for t in range(0, 240, 4)])
    assert _psnr(shown, captured[::4]) > 24.0  # measured 26.8 dB, 1552 of 2752 pixels unseen


def test_pixels_outside_the_mask_share_the_code_of_black(
    lion: ReflectanceField, lights: np.ndarray, tmp_path: Path
) -> None:
    mask = np.zeros((43, 64), np.uint8)
    mask[:, :40] = 255
    cv2.imwrite(str(tmp_path / "mask.png"), mask)
    field = import_rti(rti_capture_path(), tmp_path / "f.zarr",
                       mask=tmp_path / "mask.png")  # fmt: skip
    settings = dataclasses.replace(FIT, steps=1000, holdout=0.0)
    result = export_web(
        field, tmp_path / "web", models=("neural",), image_format="png", tiles=False,
        neural=settings,
    )  # fmt: skip
    info, codes = _codes(result.models[0].folder, "png")
    outside = codes[:, 40:].reshape(-1, 9)
    assert (outside == outside[0]).all()
    shown = np.stack([_texture(_shader(info, codes, lights[t]))[:, 40:] for t in range(0, 240, 8)])
    # Dark enough that OpenLIME's display (its 8-bit linear buffer) shows black.
    black = float(np.mean(openlime_display(shown) == 0))
    assert shown.mean() < 6.0 and black > 0.95  # measured 2.2 of 255, every value shown as 0


def test_the_command_writes_and_reports_the_neural_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = argparse.ArgumentParser(prog="rig")
    add_export_web(parser.add_subparsers(dest="command"))
    out = tmp_path / "web"
    args = parser.parse_args(["export-web", str(rti_capture_path().parent), "-o", str(out),
                              "--models", "ptm,neural", "--neural-seconds", "4",
                              "--neural-holdout", "0.1", "--quiet"])  # fmt: skip
    assert args.handler(args) == 0
    said = capsys.readouterr().out
    assert "9 planes (3 images)" in said and "neural: fitted in" in said
    assert "held-out lights:" in said and "dB against the capture" in said
    assert (out / "neural" / "plane_3.jpg").is_file() and (out / "ptm" / "plane_5.jpg").is_file()
    with pytest.raises(SystemExit):
        parser.parse_args(["export-web", "x", "-o", str(out), "--neural-holdout", "0.5"])
    assert "below 0.5" in capsys.readouterr().err
