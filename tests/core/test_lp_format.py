"""The RTI ``.lp`` format (core.lp_format): reading, writing, the fifth column."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.errors import DatasetError, InputError
from core.lp_format import LightPositions, read_lp, write_lp
from core.sample_data import rti_capture_path

LOEWENKOPF_LP = rti_capture_path()


def test_the_real_lp_file_has_240_unit_directions_over_the_upper_hemisphere() -> None:
    lights = read_lp(LOEWENKOPF_LP)
    assert len(lights) == 240 and lights.directions.shape == (240, 3)
    assert lights.files[0] == "jpg/Loewenkopf_klein_0001.jpg"
    assert lights.lines == tuple(range(2, 242))
    np.testing.assert_allclose(np.linalg.norm(lights.directions, axis=1), 1.0, atol=1e-12)
    z = lights.directions[:, 2]
    # README: "z runs from 0.02 to 0.99"; the largest is 0.99244 (rounded there).
    assert 0.02 <= z.min() < 0.025 and 0.99 < z.max() < 0.995
    # The first entry as written, to float32 rounding (the file's vectors are float32).
    np.testing.assert_allclose(
        lights.directions[0], [-0.0019356994, -0.14720464, 0.98910415], atol=1e-7
    )


def test_windows_endings_tabs_blank_lines_and_non_unit_vectors_are_accepted(
    tmp_path: Path,
) -> None:
    lp = tmp_path / "a.lp"
    lp.write_bytes(
        b"\xef\xbb\xbf2\r\njpg/a.jpg\t0.0\t0.0\t2.0\r\n\r\n  my photo.jpg   3 0 4  \r\n\r\n\r\n"
    )
    lights = read_lp(lp)
    assert lights.files == ["jpg/a.jpg", "my photo.jpg"]
    assert lights.lines == (2, 4)
    np.testing.assert_allclose(lights.directions, [[0, 0, 1], [0.6, 0, 0.8]], atol=1e-15)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"line 1: empty file"),
        ("\n\n  \n", r"line 1: empty file"),
        ("two\na.jpg 0 0 1\n", r"line 1: expected the image count .*'two'"),
        ("0\n", r"line 1: expected the image count"),
        ("-1\n", r"line 1: expected the image count"),
        ("2\na.jpg 0 0 1\n", r"line 1: announces 2 images but only 1 entries follow .*line 2"),
        ("1\na.jpg 0 0 1\nb.jpg 0 0 1\n", r"line 3: more entries than the 1 announced on line 1"),
        ("1\na.jpg 0 0 1\n\nb.jpg 0 0 1\n", r"line 4: more entries than the 1"),
        ("2\na.jpg 0 0 1\nb.jpg 0 0\n", r"line 3: expected 'filename x y z'"),
        ("2\na.jpg 0 0 1\nb.jpg 0 0 0\n", r"line 3: the direction .* has zero length"),
        ("1\na.jpg 0,5 0 1\n", r"line 2: '0,5' is not a number"),
        ("1\na.jpg x 0 1\n", r"line 2: 'x' is not a number"),
        ("1\na.jpg nan 0 1\n", r"line 2: the direction .* is not finite"),
        ("1\na.jpg 0 inf 1\n", r"line 2: the direction .* is not finite"),
    ],
)
def test_malformed_lp_files_are_refused_with_the_line(
    tmp_path: Path, text: str, match: str
) -> None:
    lp = tmp_path / "bad.lp"
    lp.write_text(text, encoding="utf-8")
    with pytest.raises(DatasetError, match=match) as caught:
        read_lp(lp)
    assert str(lp) in str(caught.value)


def test_missing_or_binary_lp_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"no such \.lp file"):
        read_lp(tmp_path / "none.lp")
    (tmp_path / "binary.lp").write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(DatasetError, match="cannot read"):
        read_lp(tmp_path / "binary.lp")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# A name whose last space-separated part is a number would read as a five-column line.
_NAMES = st.text(
    alphabet=st.characters(exclude_categories=("Cs",), exclude_characters="\r\n"),
    min_size=1,
    max_size=12,
).filter(
    lambda name: (
        name == name.strip() and not (len(name.split()) > 1 and _is_number(name.split()[-1]))
    )
)
_VECTORS = arrays(
    np.float64, 3, elements=st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
).filter(lambda v: float(np.linalg.norm(v)) > 1e-6)


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    entries=st.lists(st.tuples(_NAMES, _VECTORS), min_size=1, max_size=8),
    scale=st.one_of(st.none(), st.floats(1e-6, 1e6)),
)
def test_write_then_read_round_trips(
    tmp_path: Path, entries: list[tuple[str, np.ndarray]], scale: float | None
) -> None:
    names = [name for name, _ in entries]
    vectors = np.array([vector for _, vector in entries])
    intensities = None if scale is None else scale * np.arange(1, len(names) + 1)
    written = write_lp(tmp_path / "sub" / "round.lp", names, vectors, intensities)
    read = read_lp(tmp_path / "sub" / "round.lp")
    assert read.files == names == written.files
    assert read.lines == written.lines
    unit = vectors / np.linalg.norm(vectors, axis=1, keepdims=True)
    np.testing.assert_allclose(read.directions, unit, rtol=0, atol=1e-15)
    np.testing.assert_allclose(written.directions, unit, rtol=0, atol=1e-15)
    if intensities is None:
        assert read.intensities is None and written.intensities is None
    else:
        assert read.intensities is not None and written.intensities is not None
        np.testing.assert_array_equal(read.intensities, intensities)  # every digit
        np.testing.assert_array_equal(written.intensities, intensities)


def test_write_lp_format_and_digits(tmp_path: Path) -> None:
    direction = np.array([0.1, -0.2, 0.3])
    direction /= np.linalg.norm(direction)
    written = write_lp(tmp_path / "f.lp", ["jpg/a.jpg"], [direction])
    text = (tmp_path / "f.lp").read_text(encoding="utf-8")
    first, second, end = text.split("\n")
    assert first == "1" and end == ""
    name, *numbers = second.split(" ")
    assert name == "jpg/a.jpg"
    assert [float(n) for n in numbers] == written.directions[0].tolist()  # every digit
    np.testing.assert_allclose(written.directions[0], direction, rtol=0, atol=1e-15)
    assert not list(tmp_path.glob(".*partial*"))


@pytest.mark.parametrize(
    ("files", "directions", "match"),
    [
        ([], np.zeros((0, 3)), r"at least one image"),
        (["a.jpg"], [[0, 0, 1], [0, 0, 1]], r"shape \(1, 3\)"),
        (["a.jpg", "b.jpg"], [[0, 0, 1], [0, 0, 0]], r"line 3: direction .* zero or not finite"),
        (["a.jpg"], [[np.nan, 0, 1]], r"line 2: direction .* zero or not finite"),
        (["a.jpg", ""], [[0, 0, 1], [0, 0, 1]], r"line 3: image name '' is empty"),
        ([" a.jpg"], [[0, 0, 1]], r"line 2: .*edge whitespace"),
        (["a\nb.jpg"], [[0, 0, 1]], r"line 2: .*line break"),
        (["a.jpg", "scan 2"], [[0, 0, 1]] * 2, r"line 3: image name 'scan 2' ends in a .*number"),
    ],
)
def test_write_lp_refuses_bad_arguments(
    tmp_path: Path, files: list[str], directions: object, match: str
) -> None:
    with pytest.raises(InputError, match=match):
        write_lp(tmp_path / "bad.lp", files, directions)  # type: ignore[arg-type]
    assert not (tmp_path / "bad.lp").exists()


@pytest.mark.parametrize(
    ("intensities", "match"),
    [
        ([1.0], r"shape \(2,\)"),
        ([1.0, 0.0], r"line 3: intensity 0\.0 is not a positive finite number"),
        ([-1.0, 1.0], r"line 2: intensity -1\.0"),
        ([1.0, np.inf], r"line 3: intensity inf"),
        ([np.nan, 1.0], r"line 2: intensity nan"),
    ],
)
def test_write_lp_refuses_bad_intensities(
    tmp_path: Path, intensities: list[float], match: str
) -> None:
    with pytest.raises(InputError, match=match):
        write_lp(tmp_path / "bad.lp", ["a.jpg", "b.jpg"], [[0, 0, 1]] * 2, intensities)
    assert not (tmp_path / "bad.lp").exists()


def test_light_positions_check_their_shapes() -> None:
    with pytest.raises(InputError, match=r"shape \(2, 3\)"):
        LightPositions(files=["a", "b"], directions=np.zeros((3, 3)))
    with pytest.raises(InputError, match=r"intensities must have shape \(2,\)"):
        LightPositions(files=["a", "b"], directions=np.eye(3)[:2], intensities=np.ones(3))
    with pytest.raises(InputError, match=r"light 1 \('b'\): intensity 0\.0"):
        LightPositions(files=["a", "b"], directions=np.eye(3)[:2], intensities=np.array([1, 0.0]))


def test_a_fifth_column_gives_the_intensities(tmp_path: Path) -> None:
    lp = tmp_path / "five.lp"
    lp.write_text("2\r\nmy photo.jpg 0 0 2 0.5\r\n\tb.jpg\t3 0 4\t2e0  \r\n", encoding="utf-8")
    lights = read_lp(lp)
    assert lights.files == ["my photo.jpg", "b.jpg"]
    assert lights.intensities is not None
    np.testing.assert_array_equal(lights.intensities, [0.5, 2.0])
    np.testing.assert_allclose(lights.directions, [[0, 0, 1], [0.6, 0, 0.8]], atol=1e-15)
    assert read_lp(LOEWENKOPF_LP).intensities is None  # the four-column file


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("3\na.jpg 0 0 1 2\nb.jpg 0 0 1\nc.jpg 0 0 1 2\n", r"line 3: 4 columns, but line 2 has 5"),
        ("2\na.jpg 0 0 1\nb.jpg 0 0 1 2\n", r"line 3: 5 columns, but line 2 has 4"),
        ("2\na.jpg 0 0 1\nscan 2 0 0 1\n", r"line 3: 5 columns.*name ending in a separate number"),
        ("1\na.jpg 0 0 1 0\n", r"line 2: intensity '0' must be a positive finite number"),
        ("1\na.jpg 0 0 1 -2\n", r"line 2: intensity '-2' must be a positive"),
        ("1\na.jpg 0 0 1 nan\n", r"line 2: intensity 'nan' must be a positive"),
        ("1\na.jpg 0 0 1 inf\n", r"line 2: intensity 'inf' must be a positive"),
        ("1\na.jpg 0 0 x 2\n", r"line 2: 'x' is not a number"),
    ],
)
def test_bad_fifth_columns_are_refused_with_the_line(tmp_path: Path, text: str, match: str) -> None:
    lp = tmp_path / "bad.lp"
    lp.write_text(text, encoding="utf-8")
    with pytest.raises(DatasetError, match=match) as caught:
        read_lp(lp)
    assert str(lp) in str(caught.value)
