"""The browser viewer's uploads: a panorama or a modulation map sent by the page.

``POST /api/panorama?name=F``   a panorama file (EXR, HDR, PNG, JPEG, TIFF) in the body
``POST /api/modulation?name=F`` a modulation map (PNG, EXR, ...) in the body

Names from a request (an upload's, a path under ``/rti/``) are checked before they name a
file (:func:`name_problem`): the last part only, no control character, at most 255 bytes.
The viewer's state and its other routes are :mod:`app.live_server`.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from aiohttp import web

from app.live_server import VIEWER, json_error
from core.errors import RigError
from processing.environment import read_modulation_map
from processing.panorama import read_panorama

__all__ = ["MAX_NAME_BYTES", "add_upload_routes", "name_problem"]

#: Longest name of an upload, bytes (what Linux file systems hold).
MAX_NAME_BYTES = 255
_SUFFIXES = {".exr", ".hdr", ".png", ".jpg", ".jpeg", ".tif", ".tiff"}


def name_problem(name: str, *, limit: int = MAX_NAME_BYTES) -> str | None:
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
    problem = name_problem(name)
    if problem is not None:
        raise json_error(web.HTTPBadRequest, problem)
    suffix = Path(name).suffix.lower()
    if suffix not in _SUFFIXES:
        raise json_error(web.HTTPBadRequest, f"{name or 'the upload'}: send one of "
                     f"{', '.join(sorted(_SUFFIXES))} with ?name=FILE")  # fmt: skip
    body = await request.read()
    if not body:
        raise json_error(web.HTTPBadRequest, f"{name}: the upload is empty")
    folder = Path(tempfile.mkdtemp(dir=viewer.uploads))
    path = folder / name
    try:
        path.write_bytes(body)
    except OSError as error:  # a full disk
        path.unlink(missing_ok=True)
        raise json_error(
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
        raise json_error(web.HTTPBadRequest, str(error)) from None
    return web.json_response({"name": name, **viewer.state()})


async def _panorama(request: web.Request) -> web.Response:
    return await _upload(request, "panorama")


async def _modulation(request: web.Request) -> web.Response:
    return await _upload(request, "modulation")


def add_upload_routes(app: web.Application) -> None:
    """The upload routes (the viewer, ``app[VIEWER]``, is set already)."""
    app.router.add_post("/api/panorama", _panorama)
    app.router.add_post("/api/modulation", _modulation)
