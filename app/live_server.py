"""The browser viewer's state and its page's routes: a page, and frames over a WebSocket.

The directional light's routes are :mod:`app.light_routes`, the uploads'
:mod:`app.upload_routes`; the server that runs them all (``rig view``: start, serve, stop) is
:mod:`app.viewer_server`.

The server is aiohttp: one well-kept library for the static page, the small JSON routes,
uploads and the WebSocket the frames stream over, on asyncio, with no framework or build step
beside it. The page (``app/web/``) is plain HTML and JavaScript: it sends the controls as JSON
and shows the JPEG frames it receives; the relighting stays in Python
(:class:`render.live_session.LiveSession`), so the page shows exactly what ``rig relight``
renders.

Routes
------
``GET /``                     the page (``/viewer.js``, ``/viewer.css`` beside it)
``GET /api/state``            the field, the modes, the loaded panoramas and maps, the controls
``GET /api/live`` (WebSocket)  in: ``{"controls": {...}}`` (any subset); out: a JSON message
                              ``{"type": "frame", ...}`` followed by two binary messages, the
                              frame and the panorama (JPEG, a first byte 1 or 2 naming which);
                              then ``{"type": "warnings", ...}`` and, with ``truth`` on, the truth
                              and error pictures (bytes 3 and 4) and ``{"type": "truth", ...}``.
                              A request that arrives while a frame renders replaces any waiting
                              one, so the page never queues stale frames. A frame of
                              precomputed lighting is followed, once no control has changed for
                              0.3 s, by the exact frame (``"exact": true`` in its controls).
``GET /api/frame.png``, ``/api/frame.exr``  the current frame (tone-mapped, or linear + alpha)
``GET /api/settings.json``    the current settings

The server binds 127.0.0.1 by default: the viewer has no authentication, so exposing it on a
network is the user's explicit choice (``--host``), and a warning says what it exposes and how
to tunnel over SSH instead (:func:`app.viewer_server.exposure_warning`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from app.light_view import CapturedLight, ChosenLight, LightView
from core.errors import InputError, RigError
from core.field_store import ReflectanceField
from core.image_io import encode_picture
from core.progress import ProgressEvent, reporting_to
from processing.sampling import SAMPLERS
from render.live_session import LIVE_MODES, ZOOM_RANGE, LiveControls, LiveFrame, LiveSession
from render.output import write_image

__all__ = [
    "FRAME_JPEG_QUALITY",
    "MAX_UPLOAD_BYTES",
    "NO_LIGHT_VIEW",
    "VIEWER",
    "PendingSession",
    "add_session_routes",
    "json_error",
]

#: A pending session over a field of pixels larger than this (pixels) opens on the page's
#: request: the directional light needs no fit, relighting under a panorama does.
OPEN_ON_REQUEST_PIXELS = 8_000_000
#: JPEG quality of streamed frames: a 512 x 512 frame is about 40 KB and encodes in ~3 ms.
FRAME_JPEG_QUALITY = 90
#: Seconds without a new control before an interactive frame is refined to the exact sum.
REFINE_AFTER_S = 0.3
#: Largest upload (a 4k x 2k float EXR panorama is ~100 MB).
MAX_UPLOAD_BYTES = 256 * 1024 * 1024
#: The first byte of each binary WebSocket message: which picture follows.
PICTURE_TAGS = {"frame": 1, "panorama": 2, "truth": 3, "error": 4}
#: What a route of the light view answers (404) over a field of points.
NO_LIGHT_VIEW = "a field of points has no directional light view"
_WEB = "web"


def _page_file(name: str) -> bytes:
    return (resources.files("app") / _WEB / name).read_bytes()


class ViewerStopped(Exception):
    """The viewer stopped while long work ran for it: the work is abandoned."""


@dataclass(frozen=True)
class PendingSession:
    """A session still to be opened: the field, and how to open the session over it.

    The viewer serves its page at once and opens the session on a thread of its own (choosing
    the best mode fits models: seconds to minutes), telling the page what it is doing; a field
    of pixels gets its directional light first (:class:`app.light_view.LightView`).

    Attributes
    ----------
    field : ReflectanceField
    open : callable of a ``report(status: str)`` hook, returning the LiveSession
    source : Path, what the person opened (the page's header)
    """

    field: ReflectanceField
    open: Callable[[Callable[[str], None]], LiveSession]
    source: Path


class _Viewer:
    """The session behind the routes: one render at a time, on one worker thread."""

    def __init__(self, session: LiveSession | PendingSession, uploads: Path) -> None:
        self.uploads = uploads
        self.lock = asyncio.Lock()
        self.worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="relight")
        self.light: LightView | None = None
        self.chosen: ChosenLight | None = None
        self.captured: CapturedLight | None = None
        # The chosen method's frames run beside the session's (its choice takes a while).
        self.light_worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="light")
        self.stopping = threading.Event()
        self.on_request = False
        self._pending: PendingSession | None = None
        if session.field.sample_kind == "pixels":
            self.light = LightView(session.field, uploads / "rti")
            self.chosen = ChosenLight(session.field)
            self.captured = CapturedLight(session.field)
        self.status = "ready"
        self.field = session.field
        self.source = session.source
        self.error: str | None = None
        self.progress: ProgressEvent | None = None
        self.started = time.monotonic()
        self._session: LiveSession | None = None
        self.controls = LiveControls()
        if isinstance(session, LiveSession):
            self._opened(session)
            if self.light is not None:
                self.worker.submit(self.light.prepare)
        else:
            self.status = "starting"
            self._pending = session
            height, width = session.field.image_shape or (0, 0)
            if width * height > OPEN_ON_REQUEST_PIXELS:
                # A large capture: its light first, the panorama session (a fit over every
                # pixel: minutes, and memory) only when the person asks for it.
                if self.light is not None:
                    self.worker.submit(self.light.prepare)
                self.status = (
                    f"waiting: relighting this {width * height / 1e6:.0f}-megapixel capture "
                    "under a panorama fits models over every pixel (minutes); open it on request"
                )
                self.on_request = True
            else:
                self.open_session()

    def open_session(self) -> None:
        """Start opening the pending session (once; the page polls the state)."""
        pending, self._pending = self._pending, None
        if pending is not None:
            self.on_request = False
            self.status = "starting"
            self.worker.submit(self._open, pending)

    def check_running(self) -> None:
        """Raise :class:`ViewerStopped` once the viewer stops (long work's hooks call it)."""
        if self.stopping.is_set():
            raise ViewerStopped

    def _opened(self, session: LiveSession) -> None:
        self._session = session
        self.controls = session.initial
        self.status = "ready"

    def _open(self, pending: PendingSession) -> None:
        # The light first: on an RTI capture it is what the person came for, and it is quick.
        if self.light is not None and self.light.status == "waiting":
            self.status = "preparing the directional light"
            self.light.prepare()

        def report(status: str) -> None:
            self.check_running()
            self.status = status
            self.progress = None

        def count(event: ProgressEvent) -> None:
            self.check_running()
            self.progress = None if event.finished else event

        try:
            with reporting_to(count):
                self._opened(pending.open(report))
        except ViewerStopped:
            self.status = "stopped"
        except RigError as error:
            self.status, self.error = "failed", str(error)
        except Exception as error:  # a fault of ours: the log gets the traceback, the page why
            traceback.print_exc()
            self.status, self.error = "failed", f"internal error: {error}"

    def _field(self) -> dict[str, Any]:
        return {
            "field": str(self.source),
            "kind": self.field.sample_kind,
            "shape": list(self.field.shape),
            "image_shape": list(self.field.image_shape or ()),
        }

    @property
    def session(self) -> LiveSession:
        """The open session (the routes that need it answer 503 until it is)."""
        if self._session is None:
            raise json_error(
                web.HTTPServiceUnavailable, self.error or f"the viewer is {self.status}"
            )
        return self._session

    async def run(self, call: Any, *args: Any) -> Any:
        async with self.lock:
            return await asyncio.get_running_loop().run_in_executor(self.worker, call, *args)

    def state(self) -> dict[str, Any]:
        if self._session is None:
            progress = self.progress
            return {
                "status": self.status if progress is None else f"{self.status}: {progress}",
                "on_request": self.on_request,
                "error": self.error,
                "elapsed_s": round(time.monotonic() - self.started, 1),
                **self._field(),
            }
        s = self._session
        return {
            "status": "ready",
            **self._field(),
            "can_orbit": s.can_orbit,
            "has_truth": s.truth is not None,
            "panoramas": list(s.panoramas),
            "modulations": list(s.modulations),
            "modes": {
                "paper": s.mode(self.controls.updated({"mode": "paper"})).describe(),
                "best": s.best_reason(self.controls.panorama),
            },
            "live_modes": list(LIVE_MODES),
            "samplers": list(SAMPLERS),
            "zoom_range": list(ZOOM_RANGE),
            "controls": self.controls.to_json(),
        }


VIEWER = web.AppKey("viewer", _Viewer)


def json_error(status: type[web.HTTPException], message: str) -> web.HTTPException:
    """An HTTP error whose body is ``{"error": message}`` (the page shows the message)."""
    return status(text=json.dumps({"error": message}), content_type="application/json")


async def _index(request: web.Request) -> web.Response:
    return web.Response(body=_page_file("index.html"), content_type="text/html")


async def _static(request: web.Request) -> web.Response:
    name = request.match_info["name"]
    script, style = "text/javascript", "text/css"
    kinds = {"viewer.js": script, "light.js": script, "viewer.css": style}
    return web.Response(body=_page_file(name), content_type=kinds[name])


async def _open_session(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    viewer.open_session()
    return web.json_response(viewer.state())


async def _state(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    return web.json_response(viewer.state())


async def _frame_file(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    suffix = request.match_info["suffix"]
    frame = viewer.session.frame
    if frame is None:
        raise json_error(web.HTTPNotFound, "no frame has been rendered yet")
    if suffix == "png":
        _, body = encode_picture(frame.picture, ".png")
    else:
        path = Path(tempfile.mkdtemp(dir=viewer.uploads)) / "frame.exr"
        try:
            write_image(path, frame.image.rgb, frame.image.coverage)
        except RigError as error:  # a full disk: the write is checked
            raise json_error(web.HTTPInsufficientStorage, str(error)) from None
        body = path.read_bytes()
    return web.Response(
        body=body,
        content_type="image/png" if suffix == "png" else "image/x-exr",
        headers={"Content-Disposition": f'attachment; filename="relit.{suffix}"'},
    )


async def _settings(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    try:
        settings = viewer.session.settings()
    except InputError as error:
        raise json_error(web.HTTPNotFound, str(error)) from None
    return web.json_response(
        settings, headers={"Content-Disposition": 'attachment; filename="settings.json"'}
    )


async def _send_picture(socket: web.WebSocketResponse, tag: str, picture: Any) -> None:
    _, jpeg = encode_picture(picture, ".jpg", quality=FRAME_JPEG_QUALITY)
    await socket.send_bytes(bytes([PICTURE_TAGS[tag]]) + jpeg)


async def _send_frame(
    socket: web.WebSocketResponse,
    sequence: int,
    frame: LiveFrame,
    idle: dict[str, str],
    best: str,
) -> None:
    await socket.send_json({
        "type": "frame", "seq": sequence, "controls": frame.controls.to_json(),
        "mode": frame.mode, "best": best, "notes": list(frame.notes),
        "ms": {k: round(v * 1000.0, 2) for k, v in frame.seconds.items()},
        "points": int(frame.image.needed.sum()),
        "idle": idle,
    })  # fmt: skip
    await _send_picture(socket, "frame", frame.picture)
    await _send_picture(socket, "panorama", frame.panorama_picture)


async def _live(request: web.Request) -> web.WebSocketResponse:
    viewer = request.app[VIEWER]
    socket = web.WebSocketResponse(max_msg_size=1 << 20)
    await socket.prepare(request)
    wanted = asyncio.Event()
    pending: dict[str, Any] = {}
    sequence = 0

    async def render_loop() -> None:
        nonlocal sequence
        while not socket.closed:
            await wanted.wait()
            wanted.clear()
            changes = dict(pending)
            pending.clear()
            sequence += 1
            try:
                controls = viewer.controls.updated(changes)
                frame = await viewer.run(viewer.session.render, controls)
            except RigError as error:
                await socket.send_json({"type": "error", "seq": sequence, "message": str(error)})
                continue
            viewer.controls = controls
            idle = viewer.session.idle_controls(controls)
            best = viewer.session.best_reason(controls.panorama)
            await _send_frame(socket, sequence, frame, idle, best)
            if viewer.session.refinable(controls):
                # Interactive frames are precomputed; once the person stops, the exact sum.
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(wanted.wait(), REFINE_AFTER_S)
                if wanted.is_set():
                    continue
                sequence += 1
                exact = controls.updated({"exact": True})
                frame = await viewer.run(viewer.session.render, exact)
                await _send_frame(socket, sequence, frame, idle, best)
            if wanted.is_set():
                continue  # the next frame is wanted: its warnings, not these
            warnings = await viewer.run(viewer.session.warnings)
            await socket.send_json({"type": "warnings", "seq": sequence, "warnings": warnings})
            if controls.truth and not wanted.is_set():
                truth = await viewer.run(viewer.session.compare_truth)
                if truth is not None:
                    await _send_picture(socket, "truth", truth.picture)
                    await _send_picture(socket, "error", truth.error_picture)
                    await socket.send_json({
                        "type": "truth", "seq": sequence, "relative_rmse": truth.relative_rmse,
                        "ms": round(truth.seconds * 1000.0, 2),
                    })  # fmt: skip

    async def serve_frames() -> None:
        try:
            await render_loop()
        except ConnectionError:
            pass  # the page went away mid-frame
        except Exception as error:
            # A fault of ours, not of the controls (those are RigErrors, answered above): the
            # server's log gets the traceback, the page the reason, and the socket closes so the
            # page says it is disconnected rather than freezing.
            traceback.print_exc()
            with contextlib.suppress(ConnectionError):
                await socket.send_json({"type": "error", "message": f"internal error: {error}"})
                await socket.close()

    task = asyncio.create_task(serve_frames())
    try:
        async for message in socket:
            if message.type != WSMsgType.TEXT:
                continue
            try:
                data = json.loads(message.data)
                changes = data["controls"]
                if not isinstance(changes, dict):
                    raise TypeError
            except (ValueError, KeyError, TypeError, RecursionError):  # deep: not controls
                await socket.send_json({"type": "error", "message": 'send {"controls": {...}}'})
                continue
            pending.update(changes)
            wanted.set()
    finally:
        task.cancel()
    return socket


def add_session_routes(app: web.Application, session: LiveSession | PendingSession,
                       uploads: Path) -> None:  # fmt: skip
    """The viewer over ``session`` (uploads stored under ``uploads``) and its page's routes."""
    app[VIEWER] = _Viewer(session, uploads)
    app.router.add_get("/", _index)
    app.router.add_get("/{name:viewer\\.js|viewer\\.css|light\\.js}", _static)
    app.router.add_get("/api/state", _state)
    app.router.add_post("/api/open", _open_session)
    app.router.add_get("/api/live", _live)
    app.router.add_get("/api/frame.{suffix:png|exr}", _frame_file)
    app.router.add_get("/api/settings.json", _settings)
