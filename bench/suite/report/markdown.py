"""How the report writes its figures in Markdown: percentages, decibels, ratios and tables.

A figure that could not be measured (NaN, or a ratio to nothing) is written "-".
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

__all__ = ["decibels", "markdown_table", "percent", "ratio"]


def percent(value: float) -> str:
    """``value`` as a percentage with two decimals, e.g. ``25.71%``.

    Parameters
    ----------
    value : float, a fraction

    Returns
    -------
    str, "-" when not finite
    """
    return "-" if not math.isfinite(value) else f"{value:.2%}"


def decibels(value: float) -> str:
    """``value`` in decibels with one decimal.

    Parameters
    ----------
    value : float

    Returns
    -------
    str, "-" when not finite
    """
    return "-" if not math.isfinite(value) else f"{value:.1f}"


def ratio(value: float, reference: float) -> str:
    """``value / reference`` as a factor, e.g. ``0.76x``.

    Parameters
    ----------
    value, reference : float

    Returns
    -------
    str, "-" when either is not finite or ``reference`` is not positive
    """
    if not (math.isfinite(value) and math.isfinite(reference)) or reference <= 0:
        return "-"
    return f"{value / reference:.2f}x"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """A Markdown table's lines, and a blank line after it.

    Parameters
    ----------
    header : the column titles; rows : the cells, row by row

    Returns
    -------
    list of str
    """
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return [*lines, ""]
