"""core.store.attributes: any JSON in a store's attributes is read or refused by name."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.camera_model import PinholeCamera
from core.errors import DatasetError
from core.store.attributes import UNIT_TOLERANCE, direction_problem, read_attributes

WHERE = Path("f.zarr")
SHAPE = (2, 5, 12)  # S, T, P

CAMERA = {"azimuth_deg": 0.0, "inclination_deg": 30.0, "distance": 4.0, "fov_deg": 40.0,
          "width": 4, "height": 3}  # fmt: skip

VALID: dict[str, Any] = {
    "schema_version": 1,
    "samples": {"kind": "points"},
    "cameras": [CAMERA, CAMERA | {"azimuth_deg": 90.0}],
    "light_model": {"type": "directional", "irradiance": 1.0},
    "provenance": {"source": "simulator"},
    "radiance_digest": "ab" * 32,
    "dark_cameras": [1],
}

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 20) | st.floats() | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=4)
        | st.dictionaries(st.sampled_from(["kind", "height", "width", "x"]), children, max_size=4)
    ),
    max_leaves=12,
)


def test_valid_attributes_are_read() -> None:
    read = read_attributes(WHERE, VALID, SHAPE)
    assert read.image_shape is None and read.dark_cameras == (1,)
    assert read.cameras[1] == PinholeCamera(90.0, 30.0, width=4, height=3)
    assert read.light_model == VALID["light_model"] and read.provenance == {"source": "simulator"}
    assert read.radiance_digest == "ab" * 32
    pixels = read_attributes(
        WHERE, VALID | {"samples": {"kind": "pixels", "height": 3, "width": 4}}, SHAPE
    )
    assert pixels.image_shape == (3, 4)


def test_absent_attributes_take_their_defaults() -> None:
    read = read_attributes(WHERE, {"cameras": VALID["cameras"]}, SHAPE)
    assert read.image_shape is None and read.light_model == {} and read.provenance == {}
    assert read.radiance_digest is None and read.dark_cameras is None


# The cases of issue 28 (each gave an AttributeError, KeyError, ValueError or TypeError).
@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("samples", "points", "attribute samples is 'points'"),
        ("samples", {"kind": "pixels", "width": 4}, "attribute samples is {'kind': 'pixels'"),
        ("samples", {"kind": "voxels"}, 'a kind of "points" or "pixels"'),
        ("samples", {"kind": "pixels", "height": 2, "width": 3}, "says 2 x 3 pixels, the radi"),
        ("dark_cameras", ["x"], "attribute dark_cameras is ['x'], expected a list of camera"),
        ("dark_cameras", [2], "camera indices in 0..1"),
        ("dark_cameras", [True], "attribute dark_cameras is [True]"),
        ("light_model", "directional", "attribute light_model is 'directional', expected an"),
        ("provenance", [1, 2], "attribute provenance is [1, 2], expected an object"),
        ("radiance_digest", 5, "attribute radiance_digest is 5, expected a SHA-256"),
        ("cameras", "abc", "attribute cameras is 'abc', expected a list"),
        ("cameras", [CAMERA, 7], "attribute cameras[1] is 7"),
        ("cameras", [CAMERA, {"azimuth_deg": 0}], "camera 1 {'azimuth_deg': 0}"),
        ("cameras", [CAMERA], "1 camera records for S = 2"),
    ],
)
def test_an_attribute_of_the_wrong_type_is_named_with_its_value(
    name: str, value: object, words: str
) -> None:
    with pytest.raises(DatasetError) as raised:
        read_attributes(WHERE, VALID | {name: value}, SHAPE)
    assert str(raised.value).startswith("f.zarr: ") and words in str(raised.value)


@given(
    name=st.sampled_from(
        ["samples", "cameras", "light_model", "provenance", "radiance_digest", "dark_cameras"]
    ),
    value=json_values,
)
def test_any_json_in_an_attribute_is_read_or_refused_by_name(name: str, value: object) -> None:
    try:
        read_attributes(WHERE, VALID | {name: value}, SHAPE)
    except DatasetError as error:
        assert str(error).startswith("f.zarr: ")
        assert name.split("_")[0] in str(error) or "camera" in str(error)


def test_unit_directions_pass_and_others_are_named_by_index() -> None:
    lights = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [1.0, 0.0, 0.0]])
    assert direction_problem("light direction", lights) is None
    assert direction_problem("light direction", lights * 10) == (
        "light direction 0 is (0, 0, 10), of length 10 (2 more); light directions must be "
        "finite unit vectors"
    )
    lights[2] = np.nan
    assert direction_problem("light direction", lights) == (
        "light direction 2 is (nan, nan, nan), of length nan; light directions must be finite "
        "unit vectors"
    )


@given(
    vectors=arrays(np.float64, st.tuples(st.integers(1, 6), st.just(3)),
                   elements=st.floats(-1e3, 1e3) | st.sampled_from([np.nan, np.inf])),
)  # fmt: skip
def test_a_direction_passes_exactly_when_it_is_a_finite_unit_vector(
    vectors: np.ndarray[Any, np.dtype[np.float64]],
) -> None:
    with np.errstate(invalid="ignore", over="ignore"):
        lengths = np.linalg.norm(vectors, axis=1)
    good = np.isfinite(vectors).all() and bool(np.all(np.abs(lengths - 1) <= UNIT_TOLERANCE))
    problem = direction_problem("light direction", vectors)
    assert (problem is None) == good
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = vectors / lengths[:, None]
    if np.isfinite(unit).all():
        assert direction_problem("light direction", unit) is None
