"""The browser viewer's server (``rig view``): started on a background thread, served, stopped.

The application is the viewer's page and session routes (:mod:`app.live_server`) and the
directional light's (:mod:`app.light_routes`) and the uploads' (:mod:`app.upload_routes`), on
aiohttp.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

from aiohttp import web

from app.light_routes import add_light_routes
from app.live_server import MAX_UPLOAD_BYTES, VIEWER, PendingSession, add_session_routes
from app.upload_routes import add_upload_routes
from core.errors import InputError
from render.live_session import LiveSession

__all__ = ["ViewerServer", "build_app", "exposure_warning", "start_viewer"]


def build_app(session: LiveSession | PendingSession, uploads: Path) -> web.Application:
    """The aiohttp application of the viewer over ``session``."""
    app = web.Application(client_max_size=MAX_UPLOAD_BYTES)
    add_session_routes(app, session, uploads)
    add_light_routes(app)
    add_upload_routes(app)
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
