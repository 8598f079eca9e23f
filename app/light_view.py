"""The viewer's directional light: a field of pixels relit in the browser, on its GPU.

An RTI user's one gesture is moving the light. The page does it in WebGL2
(``app/web/light.js``) from the field's PTM and HSH fits written in the RTI web format
(:func:`render.web_export.export_web`, the format OpenLIME reads, so the page and a published
export show the same pixels): per frame
the GPU weighs the coefficient planes by the light's basis, with no round trip to the server.
This module prepares that export once per viewer, on the viewer's worker thread (the page shows
its state from the moment the URL is printed), and describes it to the page.

Large images are written as deep-zoom tiles and the page loads the tiles of the level the zoom
needs; a small one is a single image per plane.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.errors import InputError, RigError
from core.field_store import ReflectanceField
from core.progress import ProgressEvent, reporting_to

if TYPE_CHECKING:
    from render.web_export import WebModel

__all__ = ["LIGHT_MODELS", "CapturedLight", "ChosenLight", "LightView"]

#: The models the page relights with: HSH of order 3 first (the RTI tools' usual choice for
#: dome captures), PTM beside it.
LIGHT_MODELS: tuple[WebModel, ...] = ("hsh3", "ptm")
#: Images with a longer side than this (pixels) are written as deep-zoom tiles of this side.
TILED_ABOVE = 2048
TILE_SIDE = 254
#: Planes are lossless below this many pixels (a local viewer: no need to save bytes); JPEG
#: (quality 95, full chroma) above, as the published export.
LOSSLESS_PIXELS = 4_000_000


class LightView:
    """The export the page relights from: written by :meth:`prepare`, described to the page.

    Parameters
    ----------
    field : ReflectanceField of pixels
    folder : Path, an empty folder the export is written into (removed by the viewer's owner)
    """

    def __init__(self, field: ReflectanceField, folder: Path) -> None:
        self.field = field
        self.folder = folder
        self.status = "waiting"
        self.error: str | None = None
        self.started = time.monotonic()
        self.seconds: float | None = None
        self._description: dict[str, Any] | None = None

    def prepare(self) -> None:
        """Write the export (on the caller's thread; the page polls :meth:`describe`)."""
        from render.web_export import export_web

        height, width = self.field.image_shape or (0, 0)
        self.status = f"fitting {' and '.join(m.upper() for m in LIGHT_MODELS)} per pixel"
        try:
            written = export_web(
                self.field,
                self.folder,
                models=LIGHT_MODELS,
                image_format="png" if width * height <= LOSSLESS_PIXELS else "jpg",
                quality=95,
                tiles=max(width, height) > TILED_ABOVE,
                tile_size=TILE_SIDE,
            )
        except RigError as error:
            self.status, self.error = "failed", str(error)
            return
        except Exception as error:  # a fault of ours: the log gets the traceback, the page why
            traceback.print_exc()
            self.status, self.error = "failed", f"internal error: {error}"
            return
        self._description = {
            "width": written.width,
            "height": written.height,
            "normals": "rti/normals.png",
            "models": {
                m.model: {
                    "url": f"rti/{m.model}/",
                    "levels": m.levels,
                    "rms_error": round(m.rms_error, 3),
                }
                for m in written.models
            },
        }
        self.seconds = time.monotonic() - self.started
        self.status = "ready"

    def describe(self) -> dict[str, Any]:
        """What the page needs: the state, and once ready the models' folders and sizes."""
        out: dict[str, Any] = {
            "status": self.status,
            "elapsed_s": round(time.monotonic() - self.started, 1),
        }
        if self.error is not None:
            out["error"] = self.error
        if self._description is not None:
            out.update(self._description, seconds=round(self.seconds or 0.0, 2))
        return out

    def file(self, relative: str) -> Path | None:
        """A file of the export by its path relative to the folder; None outside it or absent."""
        if self.status != "ready":
            return None
        root = self.folder.resolve()
        path = (root / relative).resolve()
        if not path.is_relative_to(root) or not path.is_file():
            return None
        return path


#: Largest captured image sent whole (pixels): the page's canvas is at most 960 x 640, and
#: a larger picture costs seconds to read, encode and send before the first frame.
CAPTURED_PIXELS = 1_000_000


class CapturedLight:
    """The captured image nearest a light: what the page shows before the fits are written.

    Measured data, no fit: the page can move the light from its first second (among the
    captured lights, as a capture's own browser does) while the server writes the HSH and PTM
    planes. An image over :data:`CAPTURED_PIXELS` is sent every k-th pixel in both directions.

    Parameters
    ----------
    field : ReflectanceField of pixels
    """

    def __init__(self, field: ReflectanceField) -> None:
        from core.camera_model import rig_to_camera

        self.field = field
        #: The measured lights in the camera's frame (T, 3): x right, y up, z to the camera.
        self.directions = rig_to_camera(field.light_directions, field.cameras[0])
        height, width = field.image_shape or (0, 0)
        self.step = max(1, math.ceil(math.sqrt(width * height / CAPTURED_PIXELS)))
        #: The pictures' (width, height).
        self.size = (-(-width // self.step), -(-height // self.step))
        self._scale: float | None = None

    def _display_scale(self) -> float:
        """1 for an RTI capture (its 8-bit values); a field of radiance: its overhead image's."""
        import numpy as np

        from processing.image_quality import display_scale

        if self._scale is None:
            self._scale = 1.0
            if self.field.provenance.get("source") != "rti":
                overhead = int(np.argmax(self.directions[:, 2]))
                values = self.field.light_radiance(0, overhead)
                self._scale = display_scale(values[None, self.field.visibility[0]])
        return self._scale

    def nearest(self, light: tuple[float, float, float]) -> int:
        """Index of the measured light nearest ``light`` (camera frame, unit, z >= 0)."""
        import numpy as np

        x, y, z = light
        if not all(np.isfinite(light)) or z < 0 or abs(x * x + y * y + z * z - 1) > 1e-3:
            raise InputError(f"light {light}: a unit direction with z >= 0 is needed")
        return int(np.argmax(self.directions @ np.array(light, dtype=np.float64)))

    def picture(self, light: tuple[float, float, float]) -> tuple[bytes, int]:
        """PNG of the captured image nearest ``light``, and that light's index."""
        from core.image_io import encode_picture
        from processing.image_quality import clipped_srgb_8bit
        from render.field_view import FieldView

        index = self.nearest(light)
        values = self.field.light_radiance(0, index, widen=False)
        shown = FieldView.captured(self.field, 0).image(values, step=self.step)
        _, png = encode_picture(clipped_srgb_8bit(shown, self._display_scale()), ".png")
        return png, index


#: Largest image the server relights whole for the page (pixels): beyond, the page keeps to
#: the GPU's fits (a server frame of 24 megapixels would take seconds and a 100 MB PNG).
SERVER_PIXELS = 4_000_000


class ChosenLight:
    """The method ``rig relight --lights`` chooses, relit on the server one light at a time.

    The GPU draws the linear fits (HSH, PTM); the method the held-out choice picks (a mixture,
    adaptive, RBF, a residual over the models) is only computed here: once chosen
    (:func:`render.rung_choice.choose_light_rung`, ``fast``: no network is trained while the
    person waits), each light is one prediction of the whole image, shown as ``rig relight
    --lights`` writes it (8-bit sRGB).

    Parameters
    ----------
    field : ReflectanceField of pixels
    """

    def __init__(self, field: ReflectanceField) -> None:
        self.field = field
        self.status = "not chosen yet"
        self.method: str | None = None
        self._predictor: Any = None
        self._scale = 1.0

    def available(self) -> str | None:
        """Why the server cannot draw this field (None: it can)."""
        height, width = self.field.image_shape or (0, 0)
        if width * height > SERVER_PIXELS:
            return (
                f"the chosen method is relit on the server for images up to "
                f"{SERVER_PIXELS / 1e6:.0f} megapixels; this one has {width * height / 1e6:.1f}: "
                "the HSH and PTM fits are drawn on the GPU at any size"
            )
        return None

    def picture(
        self, light: tuple[float, float, float], *, check: Callable[[], None] | None = None
    ) -> bytes:
        """PNG of the field's view under ``light`` (camera frame: x right, y up, z to the camera).

        The first call chooses the method (seconds to minutes; :attr:`status` says which);
        ``check``, called at each step of the choice, may raise to abandon it.
        """
        import numpy as np

        from core.camera_model import camera_to_rig
        from core.image_io import encode_picture
        from processing.image_quality import clipped_srgb_8bit, display_scale
        from render.field_view import FieldView
        from render.rung_choice import choose_light_rung

        reason = self.available()
        if reason is not None:
            raise InputError(reason)
        x, y, z = light
        if not all(np.isfinite(light)) or z < 0 or abs(x * x + y * y + z * z - 1) > 1e-3:
            raise InputError(f"light {light}: a unit direction with z >= 0 is needed")
        field = self.field
        if self._predictor is None:
            what = "choosing the method by held-out error (every fast rung, two folds)"
            self.status = what

            def count(event: ProgressEvent) -> None:
                if check is not None:
                    check()
                self.status = what if event.finished else f"{what}: {event}"

            try:
                with reporting_to(count):
                    choice = choose_light_rung(field, fast=True)
            except RigError as error:  # a fit that cannot be saved, say: the next light retries
                self.status = f"could not choose the method: {error}"
                raise
            self.method = choice.describe()
            self.status = f"fitting {self.method} on every light"
            self._predictor = choice.predictor(field)
            seen = field.visibility[0]
            rti = field.provenance.get("source") == "rti"
            self._scale = 1.0 if rti else display_scale(field.camera_slab(0)[:, seen])
            self.status = "ready"
        direction = camera_to_rig(np.array([light], dtype=np.float64), field.cameras[0])
        values = self._predictor.predict(0, direction)[0]
        image = FieldView.captured(field, 0).image(values)
        _, png = encode_picture(clipped_srgb_8bit(image, self._scale), ".png")
        return png
