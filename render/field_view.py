"""A field's sample values as an image for a camera, whatever the field's geometry.

A field is either points (samples on a surface, seen by many cameras: an image is the samples
splatted for the camera, :mod:`render.splat`) or pixels (an RTI capture's one fixed view: the
samples are the image's pixels, and a mask's other pixels are no samples). Every engine, the
evaluation, the command line and the benchmarks turn values into images through
:class:`FieldView`, so that difference is written once.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField
from core.point_spacing import point_spacing
from render.splat import SplatPlan, plan_splats, splat

__all__ = ["FieldView"]


class FieldView:
    """How one camera sees a field: which samples it shows and their image.

    Parameters
    ----------
    field : ReflectanceField
    camera : PinholeCamera, the view. A field of pixels is seen only from its captured camera
        (a camera along another direction is refused); its image keeps the capture's size.
    spacing : float, optional, the points' spacing (m) when the caller has it (it takes a
        nearest-neighbour search to measure)
    index : int, optional, the captured camera this is (a field of pixels: its visibility is
        that camera's; default 0)

    Attributes
    ----------
    camera : PinholeCamera
    plan : SplatPlan or None, the splats of a field of points (None for pixels)
    needed : ndarray, shape (P,), bool, the samples the view shows
    coverage : ndarray, shape (H, W), bool, the pixels the view covers
    spacing : float or None, the points' spacing used (None for pixels)
    """

    def __init__(
        self,
        field: ReflectanceField,
        camera: PinholeCamera,
        *,
        spacing: float | None = None,
        index: int = 0,
    ) -> None:
        self.camera = camera
        self.plan: SplatPlan | None = None
        self.spacing: float | None = None
        self._shape = field.image_shape
        if field.image_shape is not None:
            if not np.allclose(camera.direction, field.camera_directions[index], atol=1e-6):
                raise InputError(
                    f"{field.path} holds the pixels of one view; it cannot be seen from "
                    f"({camera.azimuth_deg:g}, {camera.inclination_deg:g})"
                )
            seen = np.asarray(field.visibility[index], dtype=bool)
            self.needed: NDArray[np.bool_] = seen
            self.coverage: NDArray[np.bool_] = seen.reshape(field.image_shape)
            return
        assert field.points is not None and field.normals is not None
        self.spacing = point_spacing(field.points) if spacing is None else spacing
        self.plan = plan_splats(field.points, field.normals, camera, self.spacing)
        self.needed = self.plan.visible
        self.coverage = np.asarray(self.plan.coverage, dtype=bool)

    @classmethod
    def captured(
        cls, field: ReflectanceField, index: int, *, spacing: float | None = None
    ) -> FieldView:
        """The view of captured camera ``index``."""
        return cls(field, field.cameras[index], spacing=spacing, index=index)

    def image(self, values: NDArray[np.floating], *, step: int = 1) -> NDArray[np.float32]:
        """The image of per-sample ``values`` (P, 3): (H, W, 3) float32.

        A field of pixels' image is its values in place (a mask's other pixels as given:
        the engines leave them 0); ``step`` > 1 keeps every step-th pixel in each direction
        (a preview; widened to float32 after the cut). A field of points' is the values
        splatted (``step`` 1 only).
        """
        if self.plan is None:
            assert self._shape is not None
            pixels = np.asarray(values).reshape(*self._shape, 3)[::step, ::step]
            return np.ascontiguousarray(pixels, dtype=np.float32)
        if step != 1:
            raise InputError("a field of points' image is splatted whole (step 1)")
        return splat(self.plan, values)
