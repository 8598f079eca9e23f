"""The directional light's routes of the browser viewer (fields of pixels: RTI captures).

``GET /api/light``              what the light view offers: the image, the export's layers,
                                the chosen method's status, the captured lights
``GET /api/light/chosen.png``   the field under ``?x=X&y=Y&z=Z`` (camera frame) through the
                                method chosen by held-out lights (:class:`ChosenLight`)
``GET /api/light/captured.png`` the captured image nearest that light
``GET /rti/PATH``               a file of the web export the page's layer reads

The viewer's state and the other routes are :mod:`app.live_server`.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import TypeVar

from aiohttp import web

from app.light_view import CapturedLight, ChosenLight
from app.live_server import NO_LIGHT_VIEW, VIEWER, json_error
from app.upload_routes import name_problem
from core.errors import RigError

__all__ = ["add_light_routes"]

#: A light asked of the light view: a direction (x, y, z) in the camera frame.
_Light = tuple[float, float, float]
_Part = TypeVar("_Part", CapturedLight, ChosenLight)
_Drawn = TypeVar("_Drawn")


async def _light(request: web.Request) -> web.Response:
    light = request.app[VIEWER].light
    if light is None:
        raise json_error(web.HTTPNotFound, NO_LIGHT_VIEW)
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
        raise json_error(web.HTTPNotFound, NO_LIGHT_VIEW)
    try:
        x, y, z = (float(request.query[axis]) for axis in "xyz")
    except (KeyError, ValueError):
        raise json_error(web.HTTPBadRequest, "send the light as ?x=X&y=Y&z=Z (numbers)") from None
    return part, (x, y, z)


async def _drawn(executor: ThreadPoolExecutor | None, draw: Callable[[], _Drawn]) -> _Drawn:
    """``draw()`` run on ``executor`` (None: the loop's default); the project's errors are 400."""
    try:
        return await asyncio.get_running_loop().run_in_executor(executor, draw)
    except RigError as error:
        raise json_error(web.HTTPBadRequest, str(error)) from None


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
    if light is not None and name_problem(relative, limit=4096) is None:
        with contextlib.suppress(OSError, ValueError):  # a name no file system holds
            path = light.file(relative)
    if path is None:
        raise json_error(
            web.HTTPNotFound, f"{request.match_info['path']}: no such file of the export"
        )
    return web.FileResponse(path)


def add_light_routes(app: web.Application) -> None:
    """The light view's routes (the viewer, ``app[VIEWER]``, is set already)."""
    app.router.add_get("/api/light", _light)
    app.router.add_get("/api/light/chosen.png", _chosen_picture)
    app.router.add_get("/api/light/captured.png", _captured_picture)
    app.router.add_get("/rti/{path:.+}", _light_file)
