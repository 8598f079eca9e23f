"""``rig view`` in a real browser: Debian's Chromium driven by Playwright.

The page must show what the model computes: after a drag of the panorama by half its width
(a yaw of 180 degrees) the picture on screen is the engine's own relighting at that yaw, and the
highlight has moved. Screenshots are kept in ``test-artifacts/viewer/`` (or
``$RIG_TEST_ARTIFACTS/viewer``). Without a Chromium the browser tests skip, saying so; CI
installs one (``.ci/run``).
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import aiohttp
import cv2
import numpy as np
import pytest

from app.cli import main
from app.cli.view import open_session
from app.viewer_server import ViewerServer, exposure_warning, start_viewer
from core.camera_model import PinholeCamera, camera_to_rig
from core.colour import luminance
from core.directions import hemisphere_layout
from core.field_store import FieldStoreWriter, ReflectanceField
from core.sample_data import panorama_path
from render.engines.modes import open_relighter
from render.live_session import LiveSession
from render.output import display_picture
from sim.field import field_cameras, simulate_field

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# As the machine notes say: without the background-networking flags Chromium keeps trying
# hosts this closed network refuses.
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip
ARTIFACTS = Path(os.environ.get("RIG_TEST_ARTIFACTS", Path(__file__).parents[2] / "test-artifacts"))
SIZE = 160


@pytest.fixture(scope="module")
def viewer(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ViewerServer, LiveSession]]:
    path = tmp_path_factory.mktemp("viewer") / "glossy.zarr"
    simulate_field(
        path, "glossy-sphere", lights=12, cameras=field_cameras(12, width=64, height=64),
        points=3000,
    )  # fmt: skip
    session = open_session(
        ReflectanceField.open(path), [panorama_path("courtyard")], size=(SIZE, SIZE), models=None
    )
    server = start_viewer(session)
    yield server, session
    server.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if CHROMIUM is None:
        pytest.skip("no Chromium installed (apt-get install chromium; CI installs it)")
    playwright = pytest.importorskip("playwright.sync_api")
    with playwright.sync_playwright() as p:
        launched = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield launched
        launched.close()


def _shown(page: Any, selector: str, name: str) -> np.ndarray:
    """The pixels an image element shows, as the browser decoded them (RGB uint8).

    A screenshot of the element is kept as an artefact; the pixels come from the element
    itself (a screenshot at a fractional page offset gains a row).
    """
    folder = ARTIFACTS / "viewer"
    folder.mkdir(parents=True, exist_ok=True)
    page.locator(selector).screenshot(path=str(folder / f"{name}.png"))
    width, height, data = page.evaluate(
        """(selector) => {
            const img = document.querySelector(selector);
            const canvas = document.createElement("canvas");
            canvas.width = img.naturalWidth;
            canvas.height = img.naturalHeight;
            const context = canvas.getContext("2d");
            context.drawImage(img, 0, 0);
            const pixels = context.getImageData(0, 0, canvas.width, canvas.height).data;
            return [canvas.width, canvas.height, Array.from(pixels)];
        }""",
        selector,
    )
    return np.array(data, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]


def _wait_frame(page: Any, condition: str) -> None:
    page.wait_for_function(
        "() => state.meta && document.body.dataset.frame === String(state.meta.seq) && "
        f"({condition})",
        timeout=60_000,
    )
    # ... and painted: two animation frames later the screen holds it.
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


def _highlight(picture: np.ndarray) -> np.ndarray:
    """Centroid (x, y) of the brightest 1 % of the pixels."""
    y = luminance(picture.astype(np.float64))
    rows, cols = np.nonzero(y >= np.quantile(y, 0.99))
    return np.array([cols.mean(), rows.mean()])


def test_dragging_the_panorama_half_a_turn_relights_as_the_model_says(
    viewer: tuple[ViewerServer, LiveSession], browser: Any
) -> None:
    server, session = viewer
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(server.url)
    _wait_frame(page, "state.meta.controls.yaw_deg === 0 && state.meta.controls.exact")
    before = _shown(page, "#frame", "yaw-0")
    page.screenshot(path=str(ARTIFACTS / "viewer" / "page-yaw-0.png"))
    assert before.shape == (SIZE, SIZE, 3)

    box = page.locator("#panorama").bounding_box()
    middle = box["y"] + box["height"] / 2
    page.mouse.move(box["x"] + 20, middle)
    page.mouse.down()
    page.mouse.move(box["x"] + 20 + box["width"] / 2, middle, steps=8)
    page.mouse.up()
    # The drag's frames are precomputed; once it stops, the exact sum follows.
    _wait_frame(page, "state.meta.controls.yaw_deg === -180 && state.meta.controls.exact")
    after = _shown(page, "#frame", "yaw-180")
    page.screenshot(path=str(ARTIFACTS / "viewer" / "page-yaw-180.png"))
    assert page.inner_text("#yaw-value") == "-180°"

    # What the model says, computed here without the session: the best mode's engine at
    # yaw 180, shown at the session's display exposure.
    frame = session.frame
    assert frame is not None and frame.controls.yaw_deg == -180.0 and frame.controls.exact
    engine = open_relighter(session.field, session.best.mode, session.best.models)
    engine.set_lighting(session.panoramas["courtyard.exr"], yaw_deg=180.0)
    engine.set_view(frame.camera)
    image = engine.render()
    expected = display_picture(image.rgb, image.coverage, frame.exposure)
    difference = np.abs(after.astype(np.int16) - expected.astype(np.int16))
    assert difference.mean() < 2.0, "the page shows another picture than the engine renders"
    assert np.abs(after.astype(np.int16) - before.astype(np.int16)).mean() > 5.0
    moved = np.linalg.norm(_highlight(after) - _highlight(before))
    assert moved > 0.1 * SIZE, f"the highlight moved {moved:.1f} px"
    assert errors == []
    page.close()


def test_truth_error_mode_switch_and_saving(
    viewer: tuple[ViewerServer, LiveSession], browser: Any
) -> None:
    server, session = viewer
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    page.goto(server.url)
    _wait_frame(page, "true")
    page.check("#truth-on")
    page.wait_for_function("() => !document.getElementById('error-figure').hidden", timeout=60_000)
    page.wait_for_function("() => document.getElementById('truth-error').textContent !== ''")
    truth = _shown(page, "#truth", "truth")
    shown_error = float(page.inner_text("#truth-error").split()[2]) / 100
    comparison = session.compare_truth()
    assert comparison is not None
    assert shown_error == pytest.approx(comparison.relative_rmse, abs=5e-5)
    assert np.abs(truth.astype(np.int16) - comparison.picture.astype(np.int16)).mean() < 2.0
    assert comparison.relative_rmse < 0.05  # the glossy sphere is the models' own family

    # The best mode lights with the whole panorama: K and the sampler would do nothing.
    assert page.is_disabled("#k") and page.is_disabled("#sampler")
    assert "steer sampled lights" in page.inner_text("#idle-note")
    page.check("input[name=mode][value=paper]")
    _wait_frame(page, "state.meta.controls.mode === 'paper'")
    assert page.is_enabled("#k") and page.is_hidden("#idle-note")
    assert "sampled, paper" in page.inner_text("#mode-name")
    page.select_option("#k", "16")
    _wait_frame(page, "state.meta.controls.k === 16")
    page.wait_for_function("() => document.getElementById('warnings').children.length > 0")
    assert "ghosting" in page.inner_text("#warnings-summary")  # a narrow lobe, 12 lights
    page.click("#warnings-summary")  # folded until asked for
    assert "ghosting" in page.inner_text("#warnings")
    _shown(page, "#panorama", "panorama-paper-k16")

    with page.expect_download() as download:
        page.click("#save-settings")
    settings = json.loads(Path(download.value.path()).read_text())
    assert settings["controls"]["k"] == 16 and settings["mode"] == "sampled, paper"
    with page.expect_download() as download:
        page.click("#save-png")
    saved = cv2.imread(str(download.value.path()))[:, :, ::-1]
    assert session.frame is not None and np.array_equal(saved, session.frame.picture)
    page.close()


def _post(url: str, body: bytes) -> tuple[int, dict[str, Any]]:
    request = urllib.request.Request(url, data=body, method="POST")
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def test_bad_uploads_are_refused_with_the_reason(
    viewer: tuple[ViewerServer, LiveSession], tmp_path: Path
) -> None:
    server, session = viewer
    status, body = _post(server.url + "api/panorama?name=notes.txt", b"hello")
    assert status == 400 and "notes.txt" in body["error"]
    status, body = _post(server.url + "api/panorama?name=broken.exr", b"not an exr")
    assert status == 400 and "broken.exr" in body["error"]
    status, body = _post(server.url + "api/modulation?name=zero.png", _png(np.zeros((8, 16))))
    assert status == 400 and "zero" in body["error"]
    status, body = _post(server.url + "api/modulation?name=half.png", _png(np.full((8, 16), 128)))
    assert status == 200 and "half.png" in body["modulations"]
    assert "half.png" in session.modulations


def _get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=30) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as error:
        return error.code, error.read()


def test_upload_names_no_file_can_have_are_refused_with_the_reason(
    viewer: tuple[ViewerServer, LiveSession],
) -> None:
    # Each was a traceback in the server (ValueError: embedded null byte; OSError 36).
    server, _ = viewer
    picture = _png(np.full((8, 16), 128))
    status, body = _post(server.url + "api/modulation?name=a%00b.png", picture)
    assert status == 400 and "control character '\\x00'" in body["error"]
    status, body = _post(server.url + f"api/modulation?name={'n' * 300}.png", picture)
    assert status == 400 and "the name is 304 bytes long, at most 255" in body["error"]
    status, body = _post(server.url + "api/panorama?name=line%0Abreak.exr", picture)
    assert status == 400 and "control character" in body["error"]
    assert _get(server.url + "api/state")[0] == 200  # the server answers on


def test_an_upload_named_up_the_tree_stays_in_the_uploads(
    viewer: tuple[ViewerServer, LiveSession],
) -> None:
    server, session = viewer
    uploads = Path(server._uploads.name)
    status, body = _post(
        server.url + "api/modulation?name=..%2F..%2Fescaped.png", _png(np.full((8, 16), 99))
    )
    assert status == 200 and "escaped.png" in body["modulations"]
    assert "escaped.png" in session.modulations
    assert [p.relative_to(uploads).parts[1:] for p in uploads.rglob("escaped.png")] == [
        ("escaped.png",)
    ]  # in a folder of its own inside the uploads, nowhere above them
    assert not (uploads.parent / "escaped.png").exists()
    assert not (uploads.parent.parent / "escaped.png").exists()


@pytest.mark.parametrize(
    "path",
    ["%2e%2e/%2e%2e/%2e%2e/etc/passwd", "viewer.js/%2e%2e/%2e%2e/etc/passwd",
     "..%2f..%2f..%2fetc%2fpasswd", "api/frame.png%00.exr"],
)  # fmt: skip
def test_traversal_urls_of_the_page_are_not_found(
    viewer: tuple[ViewerServer, LiveSession], path: str
) -> None:
    server, _ = viewer
    status, body = _get(server.url + path)
    assert status == 404 and b"root:" not in body


def _pixel_field(path: Path, size: int = 12) -> ReflectanceField:
    """A matte disc seen from above under 25 dome lights (a field of pixels, for /rti/)."""
    lights = hemisphere_layout(25)
    ys, xs = np.mgrid[0:size, 0:size]
    u, v = (xs + 0.5) / size * 2 - 1, 1 - (ys + 0.5) / size * 2
    normals = np.stack([u, v, np.sqrt(np.clip(1 - u**2 - v**2, 0.05, 1))], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    shading = np.clip(np.einsum("hwc,tc->thw", normals, lights), 0, None)
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, size, size)
    writer = FieldStoreWriter(
        path, points=None, normals=None, light_directions=camera_to_rig(lights, camera),
        cameras=[camera], image_shape=(size, size),
    )  # fmt: skip
    for t, image in enumerate(shading):
        writer.write_slab(0, t, np.repeat(image.reshape(-1, 1), 3, axis=1).astype(np.float32))
    writer.write_visibility(0, np.ones(size * size, dtype=bool))
    writer.finish()
    return ReflectanceField.open(path)


def test_traversal_urls_of_the_export_are_not_found(tmp_path: Path) -> None:
    field = _pixel_field(tmp_path / "disc.zarr")
    with ThreadPoolExecutor(max_workers=1) as thread:  # off Playwright's loop, as above
        opened = open_session(field, [panorama_path("courtyard")], size=(32, 32), models=None)
        server = thread.submit(lambda: start_viewer(opened)).result()
    try:
        deadline = 240  # polls of 0.5 s: the export's fits, on a loaded machine
        described: dict[str, Any] = {}
        while deadline and described.get("status") not in ("ready", "failed"):
            described = json.loads(_get(server.url + "api/light")[1])
            deadline -= 1
            time.sleep(0.5)
        assert described.get("status") == "ready", described
        export = Path(server._uploads.name) / "rti"
        served = sorted(p for p in export.rglob("*") if p.is_file())[0]
        relative = served.relative_to(export).as_posix()
        # The route serves the export's files (so a 404 below is the refusal, not a dead route).
        assert _get(server.url + "rti/" + relative) == (200, served.read_bytes())
        for path in ("%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd", "..%2f..%2f..%2fetc%2fpasswd",
                     "a%00b", "a" * 300, f"{relative}%00"):  # fmt: skip
            status, body = _get(server.url + "rti/" + path)
            assert status == 404 and b"root:" not in body, path
    finally:
        server.stop()


@pytest.mark.parametrize(
    ("host", "warned"),
    [("0.0.0.0", "every network"), ("::", "every network"), ("192.168.1.20", "network of"),
     ("127.0.0.1", None), ("::1", None), ("localhost", None)],
)  # fmt: skip
def test_serving_beyond_this_machine_warns_and_says_how_to_tunnel(
    host: str, warned: str | None
) -> None:
    warning = exposure_warning(host, 8765)
    if warned is None:
        assert warning is None
    else:
        assert warning is not None and warned in warning and "no login" in warning
        assert "ssh -N -L 8765:127.0.0.1:8765 USER@THIS-MACHINE" in warning


def test_rig_view_on_every_network_prints_the_warning(
    viewer: tuple[ViewerServer, LiveSession], capsys: pytest.CaptureFixture[str]
) -> None:
    _, session = viewer
    with ThreadPoolExecutor(max_workers=1) as thread:
        server = thread.submit(lambda: start_viewer(session, host="0.0.0.0")).result()
    server.stop()
    port = server.url.rstrip("/").rsplit(":", 1)[1]
    err = capsys.readouterr().err
    assert err.startswith(f"warning: serving on 0.0.0.0:{port} answers every network")
    assert f"ssh -N -L {port}:127.0.0.1:{port}" in err


def _png(grey: np.ndarray) -> bytes:
    ok, encoded = cv2.imencode(".png", grey.astype(np.uint8))
    assert ok
    return encoded.tobytes()


def test_view_refuses_a_field_that_is_not_there(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["view", str(tmp_path / "missing.zarr")]) == 2
    assert "missing.zarr" in capsys.readouterr().err


def test_a_fault_in_rendering_reaches_the_page_and_closes_its_socket(
    viewer: tuple[ViewerServer, LiveSession], monkeypatch: pytest.MonkeyPatch
) -> None:
    server, session = viewer

    def broken(controls: object) -> None:
        raise RuntimeError("the kernel broke")

    monkeypatch.setattr(session, "render", broken)

    async def talk() -> list[Any]:
        async with (
            aiohttp.ClientSession() as client,
            client.ws_connect(server.url + "api/live") as socket,
        ):
            await socket.send_json({"controls": {"yaw_deg": 5.0}})
            return [message async for message in socket]

    # On a thread of its own: Playwright's sync API keeps an event loop on this one.
    with ThreadPoolExecutor(max_workers=1) as thread:
        messages = thread.submit(lambda: asyncio.run(asyncio.wait_for(talk(), 30.0))).result()
    texts = [json.loads(m.data) for m in messages if m.type == aiohttp.WSMsgType.TEXT]
    assert texts == [{"type": "error", "message": "internal error: the kernel broke"}]
