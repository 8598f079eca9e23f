"""Sizes as people write them, and the default memory budget of a stage (issue 18)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.cli import main
from core.errors import InputError
from core.memory_budget import (
    DEFAULT_CEILING,
    DEFAULT_FLOOR,
    default_memory_budget,
    format_size,
    parse_size,
)


@pytest.mark.parametrize(
    ("text", "size"),
    [("1000", 1000), ("512M", 512 << 20), ("2G", 2 << 30), ("2gb", 2 << 30),
     ("1.5GiB", 3 << 29), (" 64 k ", 64 << 10), ("1T", 1 << 40)],
)  # fmt: skip
def test_sizes_read_in_powers_of_1024(text: str, size: int) -> None:
    assert parse_size(text) == size


@pytest.mark.parametrize("text", ["", "G", "2X", "-1G", "0", "0.0001", "two gigabytes"])
def test_what_is_not_a_size_is_refused_by_name(text: str) -> None:
    with pytest.raises(InputError, match="memory size"):
        parse_size(text)


@given(st.integers(min_value=1, max_value=1 << 50))
def test_a_formatted_size_reads_back_within_its_rounding(size: int) -> None:
    text = format_size(size).replace(" ", "")
    # Three significant digits (half a unit in the last: 0.5 % at most), then whole bytes.
    assert abs(parse_size(text) - size) <= size * 0.005 + 1


def test_the_default_stays_between_its_bounds() -> None:
    assert DEFAULT_FLOOR <= default_memory_budget() <= DEFAULT_CEILING


def test_the_command_line_refuses_a_bad_size(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fit", "nowhere.zarr", "--max-memory", "lots"]) == 2
    assert "memory size 'lots' is not a size" in capsys.readouterr().err
