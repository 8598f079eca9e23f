"""Over 500 lines because the routes, the viewer state they share and the server are one app.

The browser viewer's server: a page, and frames over a WebSocket (``rig view``).

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
``POST /api/panorama?name=F``  a panorama file (EXR, HDR, PNG, JPEG) in the body
``POST /api/modulation?name=F`` a modulation map (PNG, EXR, ...) in the body
``GET /api/frame.png``, ``/api/frame.exr``  the current frame (tone-mapped, or linear + alpha)
``GET /api/settings.json``    the current settings

The server binds 127.0.0.1 by default: the viewer has no authentication, so exposing it on a
network is the user's explicit choice (``--host``), and a warning says what it exposes and how
to tunnel over SSH instead. Names from a request (an upload's, a path under ``/rti/``) are
checked before they name a file: the last part only, no control character, at most 255 bytes.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from aiohttp import WSMsgType, web

from app.light_view import CapturedLight, ChosenLight, LightView
from core.errors import InputError, RigError
from core.field_store import ReflectanceField
from core.image_io import encode_picture
from core.progress import ProgressEvent, reporting_to
from processing.environment import read_modulation_map
from processing.panorama import read_panorama
from processing.sampling import SAMPLERS
from render.live_session import LIVE_MODES, ZOOM_RANGE, LiveControls, LiveFrame, LiveSession
from render.output import write_image

__all__ = [
    "FRAME_JPEG_QUALITY",
    "PendingSession",
    "ViewerServer",
    "exposure_warning",
    "start_viewer",
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
#: Longest name of an upload, bytes (what Linux file systems hold).
MAX_NAME_BYTES = 255
#: The first byte of each binary WebSocket message: which picture follows.
PICTURE_TAGS = {"frame": 1, "panorama": 2, "truth": 3, "error": 4}
#: What a route of the light view answers (404) over a field of points.
NO_LIGHT_VIEW = "a field of points has no directional light view"
_WEB = "web"
_SUFFIXES = {".exr", ".hdr", ".png", ".jpg", ".jpeg", ".tif", ".tiff"}
#: A light asked of the light view: a direction (x, y, z) in the camera frame.
_Light = tuple[float, float, float]
_Part = TypeVar("_Part", CapturedLight, ChosenLight)
_Drawn = TypeVar("_Drawn")


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
            raise _error(web.HTTPServiceUnavailable, self.error or f"the viewer is {self.status}")
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


def _error(status: type[web.HTTPException], message: str) -> web.HTTPException:
    return status(text=json.dumps({"error": message}), content_type="application/json")


async def _index(request: web.Request) -> web.Response:
    return web.Response(body=_page_file("index.html"), content_type="text/html")


async def _static(request: web.Request) -> web.Response:
    name = request.match_info["name"]
    script, style = "text/javascript", "text/css"
    kinds = {"viewer.js": script, "light.js": script, "viewer.css": style}
    return web.Response(body=_page_file(name), content_type=kinds[name])


async def _light(request: web.Request) -> web.Response:
    light = request.app[VIEWER].light
    if light is None:
        raise _error(web.HTTPNotFound, NO_LIGHT_VIEW)
    viewer = request.app[VIEWER]
    chosen, captured = viewer.chosen, viewer.captured
    assert chosen is not None and captured is not None  # made with the light view
    height, width = viewer.field.image_shape or (0, 0)
    return web.json_response({
        "image": {"width": width, "height": height},
        **light.describe(),
        "chosen": {
            "status": chosen.status, "method": chosen.method, "unavailable": chosen.available(),
        },
        "captured": {
            "width": captured.size[0], "height": captured.size[1],
            "lights": len(captured.directions),
        },
    })  # fmt: skip


def _asked_light(request: web.Request, part: _Part | None) -> tuple[_Part, _Light]:
    """The light view's ``part`` a picture is asked of, and the light ``?x=X&y=Y&z=Z``."""
    if part is None:
        raise _error(web.HTTPNotFound, NO_LIGHT_VIEW)
    try:
        x, y, z = (float(request.query[axis]) for axis in "xyz")
    except (KeyError, ValueError):
        raise _error(web.HTTPBadRequest, "send the light as ?x=X&y=Y&z=Z (numbers)") from None
    return part, (x, y, z)


async def _drawn(executor: ThreadPoolExecutor | None, draw: Callable[[], _Drawn]) -> _Drawn:
    """``draw()`` run on ``executor`` (None: the loop's default); the project's errors are 400."""
    try:
        return await asyncio.get_running_loop().run_in_executor(executor, draw)
    except RigError as error:
        raise _error(web.HTTPBadRequest, str(error)) from None


async def _captured_picture(request: web.Request) -> web.Response:
    captured, light = _asked_light(request, request.app[VIEWER].captured)
    # Not on the light worker: this picture is what the page shows while that one works.
    png, index = await _drawn(None, partial(captured.picture, light))
    return web.Response(body=png, content_type="image/png", headers={"X-Light": str(index)})


async def _chosen_picture(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    chosen, light = _asked_light(request, viewer.chosen)
    png = await _drawn(
        viewer.light_worker, partial(chosen.picture, light, check=viewer.check_running)
    )
    return web.Response(body=png, content_type="image/png")


async def _light_file(request: web.Request) -> web.FileResponse:
    light = request.app[VIEWER].light
    relative = request.match_info["path"]
    path = None
    if light is not None and _name_problem(relative, limit=4096) is None:
        with contextlib.suppress(OSError, ValueError):  # a name no file system holds
            path = light.file(relative)
    if path is None:
        raise _error(web.HTTPNotFound, f"{request.match_info['path']}: no such file of the export")
    return web.FileResponse(path)


async def _open_session(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    viewer.open_session()
    return web.json_response(viewer.state())


async def _state(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    return web.json_response(viewer.state())


def _name_problem(name: str, *, limit: int = MAX_NAME_BYTES) -> str | None:
    """Why ``name`` (from a request) cannot name a file here, or None.

    A control character (a NUL byte ends a name for the operating system) or more bytes than
    a file system holds: refused with the reason rather than failing in the middle of a write.
    """
    control = next((c for c in name if ord(c) < 32 or ord(c) == 127), None)
    if control is not None:
        return (
            f"{name[:40]!r}: a file name cannot hold the control character {control!r}; rename "
            "the file"
        )
    size = len(name.encode("utf-8", "surrogateescape"))
    if size > limit:
        return f"{name[:40]}...: the name is {size} bytes long, at most {limit}; rename the file"
    return None


async def _upload(request: web.Request, kind: str) -> web.Response:
    viewer = request.app[VIEWER]
    # Only the last part of the name: "../../x.exr" is stored as x.exr, in a folder of its own.
    name = Path(request.query.get("name", "")).name
    problem = _name_problem(name)
    if problem is not None:
        raise _error(web.HTTPBadRequest, problem)
    suffix = Path(name).suffix.lower()
    if suffix not in _SUFFIXES:
        raise _error(web.HTTPBadRequest, f"{name or 'the upload'}: send one of "
                     f"{', '.join(sorted(_SUFFIXES))} with ?name=FILE")  # fmt: skip
    body = await request.read()
    if not body:
        raise _error(web.HTTPBadRequest, f"{name}: the upload is empty")
    folder = Path(tempfile.mkdtemp(dir=viewer.uploads))
    path = folder / name
    try:
        path.write_bytes(body)
    except OSError as error:  # a full disk
        path.unlink(missing_ok=True)
        raise _error(
            web.HTTPInsufficientStorage, f"{name}: cannot store the upload: {error.strerror}"
        ) from None

    def load() -> None:
        if kind == "panorama":
            panorama = read_panorama(path, resample=True)
            viewer.session.add_panorama(name, panorama)
        else:
            viewer.session.add_modulation(name, read_modulation_map(path))

    try:
        await viewer.run(load)
    except RigError as error:
        raise _error(web.HTTPBadRequest, str(error)) from None
    return web.json_response({"name": name, **viewer.state()})


async def _panorama(request: web.Request) -> web.Response:
    return await _upload(request, "panorama")


async def _modulation(request: web.Request) -> web.Response:
    return await _upload(request, "modulation")


async def _frame_file(request: web.Request) -> web.Response:
    viewer = request.app[VIEWER]
    suffix = request.match_info["suffix"]
    frame = viewer.session.frame
    if frame is None:
        raise _error(web.HTTPNotFound, "no frame has been rendered yet")
    if suffix == "png":
        _, body = encode_picture(frame.picture, ".png")
    else:
        path = Path(tempfile.mkdtemp(dir=viewer.uploads)) / "frame.exr"
        try:
            write_image(path, frame.image.rgb, frame.image.coverage)
        except RigError as error:  # a full disk: the write is checked
            raise _error(web.HTTPInsufficientStorage, str(error)) from None
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
        raise _error(web.HTTPNotFound, str(error)) from None
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


def build_app(session: LiveSession | PendingSession, uploads: Path) -> web.Application:
    """The aiohttp application of the viewer over ``session``."""
    app = web.Application(client_max_size=MAX_UPLOAD_BYTES)
    app[VIEWER] = _Viewer(session, uploads)
    app.router.add_get("/", _index)
    app.router.add_get("/{name:viewer\\.js|viewer\\.css|light\\.js}", _static)
    app.router.add_get("/api/light", _light)
    app.router.add_get("/api/light/chosen.png", _chosen_picture)
    app.router.add_get("/api/light/captured.png", _captured_picture)
    app.router.add_get("/rti/{path:.+}", _light_file)
    app.router.add_get("/api/state", _state)
    app.router.add_post("/api/open", _open_session)
    app.router.add_get("/api/live", _live)
    app.router.add_post("/api/panorama", _panorama)
    app.router.add_post("/api/modulation", _modulation)
    app.router.add_get("/api/frame.{suffix:png|exr}", _frame_file)
    app.router.add_get("/api/settings.json", _settings)
    return app


#: Seconds a request under way (a frame being streamed, an upload) gets to finish once the
#: viewer stops; then it is cancelled and its socket closed. An open page holds its WebSocket
#: for as long as it is open: aiohttp's default (60 s) would keep Ctrl-C waiting that long.
STOP_GRACE_S = 1.0
#: Seconds :meth:`ViewerServer.stop` waits for the server's loop to shut down and stop.
STOP_TIMEOUT_S = 10.0
#: Seconds of waiting for the work under way when stopping before saying so.
STOP_NOTICE_S = 1.0


@dataclass
class ViewerServer:
    """A running viewer: its URL, and how to stop it.

    ``_stopped`` is set by the loop's thread once its loop has stopped: the only sign of it
    to trust after an interrupted :meth:`wait`. (On Python 3.11 a ``Thread.join`` that
    Ctrl-C interrupts marks the thread finished while it runs on, so a later ``join`` returns
    at once; closing the loop then failed with "Cannot close a running event loop".)
    """

    url: str
    _loop: asyncio.AbstractEventLoop
    _runner: web.AppRunner
    _thread: threading.Thread
    _uploads: tempfile.TemporaryDirectory[str]
    _stopped: threading.Event

    def stop(self) -> None:
        """Stop serving, let the render under way finish, and remove the uploads.

        Safe after an interrupted :meth:`wait` and when called twice. The runner is shut
        down inside the loop (its sockets, the requests under way, the tasks left), then
        the loop is stopped from this thread and closed once it no longer runs.
        """
        if not self._stopped.is_set():
            shutdown = asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop)
            with contextlib.suppress(TimeoutError):  # the loop is stopped all the same
                shutdown.result(timeout=STOP_TIMEOUT_S)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._stopped.wait(timeout=STOP_TIMEOUT_S)
        if self._stopped.is_set() and not self._loop.is_closed():
            self._loop.close()
        # A frame under way on a worker ends, and what is queued behind it is dropped; the
        # session's opening and the chosen method's choice stop at their next stage or step
        # (their hooks raise once the viewer stops). What remains may take a while, so the
        # person who pressed Ctrl-C is told rather than left waiting in silence.
        viewer = self._runner.app[VIEWER]
        viewer.stopping.set()
        workers = (viewer.worker, viewer.light_worker)
        for worker in workers:
            worker.shutdown(wait=False, cancel_futures=True)

        def finish() -> None:
            for worker in workers:
                worker.shutdown()

        finishing = threading.Thread(target=finish, name="rig-view-stop", daemon=True)
        finishing.start()
        finishing.join(timeout=STOP_NOTICE_S)
        if finishing.is_alive():
            print("rig view: waiting for the work under way to finish", file=sys.stderr,
                  flush=True)  # fmt: skip
            finishing.join()
        self._uploads.cleanup()

    async def _shutdown(self) -> None:
        await self._runner.cleanup()
        current = asyncio.current_task()
        left = [task for task in asyncio.all_tasks() if task is not current]
        for task in left:
            task.cancel()
        await asyncio.gather(*left, return_exceptions=True)

    def wait(self) -> None:
        """Serve until interrupted (Ctrl-C, or SIGTERM under ``rig``)."""
        self._stopped.wait()


def exposure_warning(host: str, port: int) -> str | None:
    """What to say when serving on ``host`` reaches beyond this machine; None for loopback.

    The viewer has no login: a page of the field, and uploads into this machine, for anyone
    who can reach the port. The warning says how to view from elsewhere without that.
    """
    try:
        address = ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        if host.lower() in ("localhost", "localhost.localdomain"):
            return None
        every = host in ("", "*")
    else:
        if address.is_loopback:
            return None
        every = address.is_unspecified
    reach = "every network this machine is on" if every else f"the network of {host}"
    return (
        f"serving on {host or '*'}:{port} answers {reach}, and the viewer has no login: "
        "anyone who can reach it sees the field and can send this machine files. To view "
        "from another machine, serve on 127.0.0.1 (the default) and tunnel instead: run "
        f"`ssh -N -L {port}:127.0.0.1:{port} USER@THIS-MACHINE` there and open "
        f"http://127.0.0.1:{port}/"
    )


def start_viewer(
    session: LiveSession | PendingSession, *, host: str = "127.0.0.1", port: int = 0
) -> ViewerServer:
    """Serve the viewer on ``host``:``port`` (0: a free port) from a background thread.

    Beyond this machine (``--host 0.0.0.0``) a warning on stderr says what that exposes and
    how to tunnel instead (:func:`exposure_warning`).
    """
    uploads = tempfile.TemporaryDirectory(prefix="rig-view-")
    loop = asyncio.new_event_loop()
    runner = web.AppRunner(
        build_app(session, Path(uploads.name)), access_log=None, shutdown_timeout=STOP_GRACE_S
    )
    try:
        loop.run_until_complete(runner.setup())
        loop.run_until_complete(web.TCPSite(runner, host, port).start())
    except BaseException as error:
        loop.run_until_complete(runner.cleanup())
        loop.close()
        uploads.cleanup()
        if isinstance(error, OSError):
            reason = error.strerror or error
            raise InputError(f"cannot serve on {host}:{port}: {reason}") from None
        raise
    bound = runner.addresses[0]
    shown = f"[{bound[0]}]" if ":" in str(bound[0]) else bound[0]
    warning = exposure_warning(host, int(bound[1]))
    if warning is not None:
        print(f"warning: {warning}", file=sys.stderr, flush=True)
    stopped = threading.Event()

    def serve() -> None:
        try:
            loop.run_forever()
        finally:
            stopped.set()

    thread = threading.Thread(target=serve, name="rig-view", daemon=True)
    thread.start()
    return ViewerServer(f"http://{shown}:{bound[1]}/", loop, runner, thread, uploads, stopped)
