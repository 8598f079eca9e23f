"""``rig view``'s directional light in a real browser (Chromium, WebGL2 on SwiftShader).

An RTI user moves the light: dragging the hemisphere pad must move the highlight the way the
light moved, and what the page draws at a light must be what ``rig relight --lights --method
hsh3-8bit`` writes at that light, within the 8-bit quantisation of the coefficient planes.
Screenshots are kept in ``test-artifacts/light-view/``.
"""

from __future__ import annotations

import json
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from app import light_view, live_server
from app.cli import main
from app.cli.view import open_session
from app.live_server import PendingSession
from app.viewer_server import ViewerServer, start_viewer
from core.camera_model import PinholeCamera, camera_to_rig, rig_to_camera
from core.colour import luminance
from core.directions import hemisphere_layout
from core.field_store import FieldStoreWriter, ReflectanceField
from core.sample_data import panorama_path, rti_capture_path
from processing.rti import import_rti
from tests.app.test_viewer import ARTIFACTS, CHROMIUM, CHROMIUM_ARGS
from tests.full_disk import run_limited

FOLDER = ARTIFACTS / "light-view"
#: WebGL2 without a GPU: Chromium's software rasteriser.
WEBGL_ARGS = [*CHROMIUM_ARGS, "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]


def _sphere_field(path: Path, size: int = 48) -> ReflectanceField:
    """A glossy hemisphere seen from above under 49 dome lights (pixels; linear values)."""
    lights = hemisphere_layout(49)
    ys, xs = np.mgrid[0:size, 0:size]
    u = (xs + 0.5) / size * 2 - 1
    v = 1 - (ys + 0.5) / size * 2
    inside = u**2 + v**2 < 1
    normals = np.stack([u, v, np.sqrt(np.clip(1 - u**2 - v**2, 0, 1))], axis=-1)
    halfway = lights + np.array([0.0, 0.0, 1.0])
    halfway /= np.linalg.norm(halfway, axis=1, keepdims=True)
    diffuse = np.clip(np.einsum("hwc,tc->thw", normals, lights), 0, None)
    gloss = np.clip(np.einsum("hwc,tc->thw", normals, halfway), 0, None) ** 12
    values = np.where(inside, 0.35 * diffuse + 0.5 * gloss, 0.02)[..., None] * [1.0, 0.9, 0.8]
    camera = PinholeCamera(0.0, 0.0, 10.0, 10.0, size, size)
    writer = FieldStoreWriter(
        path, points=None, normals=None, light_directions=camera_to_rig(lights, camera),
        cameras=[camera], image_shape=(size, size),
    )  # fmt: skip
    for t, image in enumerate(values):
        writer.write_slab(0, t, image.reshape(-1, 3).astype(np.float32))
    writer.write_visibility(0, np.ones(size * size, dtype=bool))
    writer.finish()
    return ReflectanceField.open(path)


def _off_the_loop(call: Any) -> Any:
    """Run ``call`` on another thread: Playwright's sync API holds this thread's event loop."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(call).result()


def _serve(field: ReflectanceField, source: Path) -> ViewerServer:
    # As `rig view` does: the page is served at once, the session opened behind it.
    panoramas = [panorama_path("courtyard")]
    return _off_the_loop(
        lambda: start_viewer(
            PendingSession(
                field,
                lambda report: open_session(
                    field, panoramas, size=(64, 64), models=None, source=source, report=report
                ),
                source,
            )
        )
    )


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if CHROMIUM is None:
        pytest.skip("no Chromium installed (apt-get install chromium; CI installs it)")
    playwright = pytest.importorskip("playwright.sync_api")
    with playwright.sync_playwright() as p:
        launched = p.chromium.launch(executable_path=CHROMIUM, args=WEBGL_ARGS)
        yield launched
        launched.close()


def _open_page(browser: Any, url: str) -> tuple[Any, list[str]]:
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(url)
    # The captured images first, then the fits: wait for a frame drawn from a fit.
    page.wait_for_function("() => lightView.state.fitsReady", timeout=300_000)
    before = page.evaluate("() => Number(document.body.dataset.lightFrame || 0)")
    page.evaluate("() => lightView.setLight(0, 0)")
    page.wait_for_function(f"() => Number(document.body.dataset.lightFrame || 0) > {before}",
                           timeout=300_000)  # fmt: skip
    return page, errors


def _snapshot(page: Any) -> np.ndarray:
    """The page's image at its own resolution, as its shader draws it (RGB uint8)."""
    width, height, data = page.evaluate("() => lightView.snapshot()")
    return np.array(data, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]


def _bright_centroid(picture: np.ndarray) -> np.ndarray:
    y = luminance(picture.astype(np.float64))
    rows, cols = np.nonzero(y >= np.quantile(y, 0.98))
    return np.array([cols.mean(), rows.mean()])


def test_dragging_the_light_pad_moves_the_highlight(browser: Any, tmp_path: Path) -> None:
    field = _sphere_field(tmp_path / "sphere.zarr")
    server = _serve(field, tmp_path / "sphere.zarr")
    try:
        page, errors = _open_page(browser, server.url)
        FOLDER.mkdir(parents=True, exist_ok=True)
        # The pad stays where it was when the panorama session opens and the status changes.
        before = page.locator("#light-pad").bounding_box()
        page.wait_for_function("() => !document.body.classList.contains('preparing')",
                               timeout=300_000)  # fmt: skip
        assert page.locator("#light-pad").bounding_box() == before
        pictures = []
        for name, fraction in (("left", 0.2), ("right", 0.8)):
            pad = page.locator("#light-pad").bounding_box()
            centre_y = pad["y"] + pad["height"] / 2
            # A drag across the pad, ending where the light should be.
            page.mouse.move(pad["x"] + pad["width"] / 2, centre_y)
            page.mouse.down()
            page.mouse.move(pad["x"] + pad["width"] * fraction, centre_y, steps=6)
            page.mouse.up()
            page.wait_for_function("() => !lightView.state.pending")
            light = page.evaluate("() => lightView.state.light")
            assert light[0] == pytest.approx(fraction * 2 - 1, abs=0.05) and abs(light[1]) < 0.05
            angles = page.inner_text("#light-angles")
            assert ("azimuth 180.0°" if name == "left" else "azimuth 0.0°") in angles
            page.screenshot(path=str(FOLDER / f"sphere-{name}.png"))
            pictures.append(_snapshot(page))
        left, right = (_bright_centroid(p) for p in pictures)
        size = pictures[0].shape[1]
        # The highlight sits where the normal halves light and view: left of centre, then right.
        assert left[0] < 0.4 * size < 0.6 * size < right[0], (left, right)
        assert abs(left[1] - right[1]) < 0.1 * size
        assert errors == []
        page.close()
    finally:
        _off_the_loop(server.stop)


def test_the_page_draws_what_rig_relight_writes_at_that_light(browser: Any, tmp_path: Path) -> None:
    capture = rti_capture_path()
    field = import_rti(capture, tmp_path / "lion.zarr")
    server = _serve(field, capture)
    try:
        page, errors = _open_page(browser, server.url)
        described = json.loads(urllib.request.urlopen(server.url + "api/light").read())
        assert described["status"] == "ready" and set(described["models"]) == {"hsh3", "ptm"}
        assert page.inner_text("#field").startswith(str(capture))  # not the temporary store
        light = np.array([0.45, 0.3, 0.0])
        light[2] = np.sqrt(1 - light[0] ** 2 - light[1] ** 2)
        page.evaluate(f"() => lightView.setLight({light[0]}, {light[1]})")
        page.wait_for_function("() => !lightView.state.pending")
        page.screenshot(path=str(FOLDER / "lion.png"))
        shown = _snapshot(page)

        lp = tmp_path / "one.lp"
        lp.write_text(f"1\nquery {light[0]:.9f} {light[1]:.9f} {light[2]:.9f}\n")
        assert main([
            "relight", str(capture), "--lights", str(lp), "--method", "hsh3-8bit",
            "-o", str(tmp_path / "relit"),
        ]) == 0  # fmt: skip
        written = np.asarray(cv2.imread(str(tmp_path / "relit" / "query.png")))[:, :, ::-1]
        assert written.shape == shown.shape == (43, 64, 3)

        # The bound: each plane is rounded to its 8-bit level (half a step of its range),
        # weighted by the basis at this light, and both pictures round to 8 bits.
        info = json.loads(urllib.request.urlopen(server.url + "rti/hsh3/info.json").read())
        weights = page.evaluate(f"() => lightView.weights('hsh', [{', '.join(map(str, light))}])")
        scale = np.reshape(info["materials"][0]["scale"], (-1, 3))
        bound = np.abs(weights) @ scale * 255 / 510 + 1.0  # levels, per channel
        difference = np.abs(shown.astype(np.int16) - written.astype(np.int16))
        assert (difference <= np.ceil(bound)).all(), (difference.max(), bound)
        assert difference.mean() < 1.0
        assert errors == []
        page.close()
    finally:
        _off_the_loop(server.stop)


def test_deep_zoom_tiles_draw_the_same_image(
    browser: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Tiles as a 24-megapixel capture gets them, on a small image: 16-pixel tiles, 3 levels.
    field = _sphere_field(tmp_path / "sphere.zarr")
    pictures = {}
    for tiled in (False, True):
        if tiled:
            monkeypatch.setattr(light_view, "TILED_ABOVE", 32)
            monkeypatch.setattr(light_view, "TILE_SIDE", 16)
        server = _serve(field, tmp_path / "sphere.zarr")
        try:
            page, errors = _open_page(browser, server.url)
            levels = page.evaluate("() => lightView.state.model.levels.length")
            assert levels == (3 if tiled else 1)
            page.evaluate("() => lightView.setLight(-0.3, 0.5)")
            pictures[tiled] = _snapshot(page)
            if tiled:
                # Zoomed out to a quarter, the page draws the coarsest level's single tile.
                page.evaluate("() => { lightView.state.view = {scale: 0.25, x: 0, y: 0}; }")
                page.evaluate("() => lightView.setLight(-0.3, 0.5)")
                page.wait_for_function("() => !lightView.state.pending")
                drawn = page.evaluate("() => [...lightView.state.tiles.keys()]")
                assert "hsh3/0/0_0" in drawn and any(k.startswith("hsh3/2/") for k in drawn)
            assert errors == []
            page.close()
        finally:
            _off_the_loop(server.stop)
    # The finest level's tiles reassemble the image: the same planes, the same pixels (the
    # overlap only feeds filtering across a seam).
    difference = np.abs(pictures[True].astype(np.int16) - pictures[False].astype(np.int16))
    assert difference.max() <= 1, difference.max()


def test_the_chosen_method_is_relit_by_the_server(browser: Any, tmp_path: Path) -> None:
    field = _sphere_field(tmp_path / "sphere.zarr", size=32)
    server = _serve(field, tmp_path / "sphere.zarr")
    try:
        page, errors = _open_page(browser, server.url)
        page.select_option("#light-model", "chosen")
        before = page.evaluate("() => Number(document.body.dataset.lightFrame)")
        page.evaluate("() => lightView.setLight(0.4, -0.2)")
        page.wait_for_function(
            f"() => Number(document.body.dataset.lightFrame) > {before}", timeout=600_000
        )
        light = page.evaluate("() => lightView.state.light")
        shown = _snapshot(page)
        page.screenshot(path=str(FOLDER / "sphere-chosen.png"))
        assert "server" in page.inner_text("#light-status")
        method = json.loads(urllib.request.urlopen(server.url + "api/light").read())["chosen"]
        assert method["status"] == "ready" and method["method"]
        # What the server computes for that light, made here anew: the same choice, the same
        # picture, drawn by the page byte for byte.
        png = light_view.ChosenLight(field).picture(tuple(light))
        expected = np.asarray(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR))
        expected = expected[:, :, ::-1]
        assert np.array_equal(shown, expected)
        bad = urllib.request.Request(server.url + "api/light/chosen.png?x=2&y=0&z=0")
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(bad)
        assert refused.value.code == 400 and "unit direction" in refused.value.read().decode()
        assert errors == []
        page.close()
    finally:
        _off_the_loop(server.stop)


def test_the_captured_images_are_shown_before_the_fits(browser: Any, tmp_path: Path) -> None:
    field = _sphere_field(tmp_path / "sphere.zarr", size=32)
    server = _serve(field, tmp_path / "sphere.zarr")
    try:
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(server.url)
        page.wait_for_function("() => Number(document.body.dataset.lightFrame || 0) > 0",
                               timeout=300_000)  # fmt: skip
        # The first frame is measured data: no fit was needed to draw it.
        assert page.evaluate("() => lightView.state.firstModel") == "captured"
        FOLDER.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(FOLDER / "sphere-captured-first.png"))
        page.wait_for_function("() => lightView.state.fitsReady", timeout=300_000)
        page.select_option("#light-model", "captured")
        captured = light_view.CapturedLight(field)
        for t in (3, 40):  # the page asked for a measured light: that light's own image
            x, y = captured.directions[t][:2]
            before = page.evaluate("() => Number(document.body.dataset.lightFrame)")
            page.evaluate(f"() => lightView.setLight({x}, {y})")
            page.wait_for_function(
                f"() => Number(document.body.dataset.lightFrame) > {before}", timeout=300_000
            )
            shown = _snapshot(page)
            png, index = captured.picture(tuple(page.evaluate("() => lightView.state.light")))
            assert index == t and f"light {t + 1} of 49" in page.inner_text("#light-status")
            expected = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
            assert np.array_equal(shown, expected)
            image = field.light_radiance(0, t).reshape(32, 32, 3)
            assert np.abs(expected / 255.0 - clipped_display(field, image)).max() < 1 / 255 + 1e-6
        assert errors == []
        page.close()
    finally:
        _off_the_loop(server.stop)


def clipped_display(field: ReflectanceField, image: np.ndarray) -> np.ndarray:
    """``image`` as ``rig relight --lights`` shows a field of radiance (0..1 display values)."""
    from core.colour import linear_to_srgb
    from processing.image_quality import display_scale

    lights = rig_to_camera(field.light_directions, field.cameras[0])
    overhead = field.light_radiance(0, int(np.argmax(lights[:, 2])))
    scale = display_scale(overhead[None, field.visibility[0]])
    return np.asarray(linear_to_srgb(np.clip(image * scale, 0.0, 1.0)))


def test_a_large_capture_opens_its_panorama_session_on_request(
    browser: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # As a 24-megapixel capture: the light at once, the panorama session's fit when asked.
    monkeypatch.setattr(live_server, "OPEN_ON_REQUEST_PIXELS", 1000)
    field = _sphere_field(tmp_path / "sphere.zarr", size=32)
    server = _serve(field, tmp_path / "sphere.zarr")
    try:
        page, errors = _open_page(browser, server.url)
        page.wait_for_selector("#open-session", state="visible")
        assert "on request" in page.inner_text("#status")
        assert page.evaluate("() => document.body.classList.contains('preparing')")
        page.click("#open-session")
        page.wait_for_function("() => !document.body.classList.contains('preparing')",
                               timeout=600_000)  # fmt: skip
        page.wait_for_function("() => document.getElementById('status').textContent === 'live'",
                               timeout=600_000)  # fmt: skip
        assert page.is_hidden("#open-session")
        assert errors == []
        page.close()
    finally:
        _off_the_loop(server.stop)


_PICTURE = """
import sys
from app.light_view import ChosenLight
from core.errors import InputError
from core.field_store import ReflectanceField
chosen = ChosenLight(ReflectanceField.open(sys.argv[1]))
try:
    chosen.picture((0.0, 0.0, 1.0))
except InputError as error:
    print("failed:", error)
print("status:", chosen.status)
"""


def test_a_method_that_cannot_be_chosen_says_why_in_the_status(tmp_path: Path) -> None:
    # The choice saves the models' fit beside the store; on a full disk (a real file size
    # limit, in a child) it fails, and the page's status says so rather than "choosing".
    store = _sphere_field(tmp_path / "sphere.zarr", size=16).path
    argv = [sys.executable, "-c", _PICTURE, str(store)]
    done = run_limited(argv, limit=1 << 30)  # compiles and caches the kernels (files too)
    assert "status: ready" in done.stdout, done.stdout + done.stderr
    for path in tmp_path.glob("sphere.zarr.models*"):
        path.unlink()
    done = run_limited(argv, limit=4_000)
    assert "failed: " in done.stdout and "cannot write" in done.stdout, done.stdout + done.stderr
    assert "status: could not choose the method: " in done.stdout
