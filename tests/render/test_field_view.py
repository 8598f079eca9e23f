from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import ReflectanceField
from core.image_io import write_uint8
from core.point_spacing import point_spacing
from processing.rti import import_rti
from render.field_view import FieldView
from render.splat import plan_splats, splat
from sim.field import field_cameras, simulate_field
from sim.rti_capture import write_rti_capture


def test_a_field_of_points_is_splatted_for_any_camera(tmp_path: Path) -> None:
    simulate_field(tmp_path / "f.zarr", "glossy-sphere", lights=6,
                   cameras=field_cameras(4, width=24, height=24), points=500)  # fmt: skip
    field = ReflectanceField.open(tmp_path / "f.zarr")
    assert field.points is not None and field.normals is not None
    camera = replace(field.cameras[1], azimuth_deg=field.cameras[1].azimuth_deg + 17.0)
    view = FieldView(field, camera)
    plan = plan_splats(field.points, field.normals, camera, point_spacing(field.points))
    values = np.random.default_rng(0).random((field.shape[2], 3), dtype=np.float32)
    assert np.array_equal(view.image(values), splat(plan, values))
    assert np.array_equal(view.coverage, plan.coverage) and np.array_equal(
        view.needed, plan.visible
    )
    assert view.spacing == pytest.approx(point_spacing(field.points))
    captured = FieldView.captured(field, 2, spacing=view.spacing)
    assert captured.camera == field.cameras[2] and captured.image(values).shape == (24, 24, 3)


def test_a_field_of_pixels_is_its_one_view_with_its_mask(tmp_path: Path) -> None:
    directions = hemisphere_layout(9, "fibonacci")
    images = np.random.default_rng(1).random((9, 5, 7, 3)).astype(np.float32)
    lp = write_rti_capture(tmp_path / "capture", "dome", images, directions, scale=1.0)
    mask = np.ones((5, 7), dtype=bool)
    mask[0, :3] = False
    write_uint8(
        tmp_path / "mask.png", np.repeat(np.where(mask, 255, 0).astype(np.uint8)[..., None], 3, 2)
    )
    field = import_rti(lp, tmp_path / "field.zarr", mask=tmp_path / "mask.png")
    view = FieldView(field, field.cameras[0])
    assert view.plan is None and view.spacing is None
    assert np.array_equal(view.coverage, mask) and np.array_equal(view.needed, mask.ravel())
    values = np.arange(35 * 3, dtype=np.float32).reshape(35, 3)
    assert np.array_equal(view.image(values), values.reshape(5, 7, 3))
    other = replace(field.cameras[0], azimuth_deg=field.cameras[0].azimuth_deg + 30.0,
                    inclination_deg=45.0)  # fmt: skip
    with pytest.raises(InputError, match="holds the pixels of one view"):
        FieldView(field, other)
