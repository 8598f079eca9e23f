"""GRBL 1.1's EEPROM: the settings (``$N=value``, ``$$``) and the startup lines (``$Nx=line``).

The settings are a plain ``dict[int, float]`` (number to value) that the machine owns; this
module only knows their defaults, which are integers, and how GRBL checks and prints them. The
two startup lines are plain strings; :func:`startup_line_command` reads the command that
stores one (the machine validates the line by executing it, as ``system.c`` does).
"""

from __future__ import annotations

from collections.abc import Mapping

from sim.grbl.words import NUMBER, Refused

__all__ = [
    "DEFAULT_SETTINGS",
    "N_STARTUP_LINES",
    "setting_lines",
    "settings_with",
    "startup_line_command",
    "startup_listing",
    "store_setting",
]

DEFAULT_SETTINGS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0,
    30: 1000, 31: 0, 32: 0,
    100: 250.0, 101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0,
    120: 10.0, 121: 10.0, 122: 10.0, 130: 200.0, 131: 200.0, 132: 200.0,
}  # fmt: skip
"""GRBL 1.1's default settings (``$$`` of a fresh controller)."""

N_STARTUP_LINES = 2
"""GRBL's ``N_STARTUP_LINE``: ``$N0`` and ``$N1``."""

_INTEGER_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32})
_ZERO_DECIMAL_SETTINGS = frozenset({30, 31})


def settings_with(overrides: Mapping[int, float] | None) -> dict[int, float]:
    """The default settings with ``overrides`` applied (keys and values coerced to numbers)."""
    settings = dict(DEFAULT_SETTINGS)
    settings.update({int(k): float(v) for k, v in (overrides or {}).items()})
    return settings


def setting_lines(settings: Mapping[int, float]) -> list[str]:
    """The ``$$`` listing, ``$N=value`` in number order, formatted as GRBL prints each."""
    return [f"${number}={_setting_text(number, settings[number])}" for number in sorted(settings)]


def store_setting(settings: dict[int, float], command: str) -> None:
    """Apply ``N=value`` (a ``$`` line without its ``$``) with GRBL's checks.

    Parameters
    ----------
    settings : the machine's settings, changed in place
    command : the line after the ``$``, starting with a digit

    Raises
    ------
    Refused
        With GRBL's status code (2 bad number, 3 bad command or unknown setting, 4 negative,
        6 step pulse under 3 us, 10 soft limits without homing); nothing is changed then.
    """
    number = NUMBER.match(command)
    if not number:
        raise Refused(2)
    rest = command[number.end() :]
    if not rest.startswith("="):
        raise Refused(3)
    value = NUMBER.match(rest, 1)
    if not value:
        raise Refused(2)
    parameter, amount = float(number.group()), float(value.group())
    if value.end() != len(rest) or parameter > 255 or parameter != int(parameter):
        raise Refused(3)
    key = int(parameter)
    if amount < 0:
        raise Refused(4)
    if key not in settings:
        raise Refused(3)
    if key in _INTEGER_SETTINGS:
        amount = float(int(amount))
    if key == 0 and amount < 3:
        raise Refused(6)
    if key == 20 and amount and not settings[22]:
        raise Refused(10)
    settings[key] = amount
    if key == 22 and not amount:
        settings[20] = 0.0  # GRBL clears soft limits with homing


def startup_line_command(command: str) -> tuple[int, str]:
    """Read ``Nx=line`` (a ``$`` line without its ``$``): the index ``x`` and the line.

    Raises
    ------
    Refused
        ``error:2`` without a number after the ``N``, ``error:3`` without the ``=``.
    """
    number = NUMBER.match(command, 1)
    if not number:
        raise Refused(2)
    rest = command[number.end() :]
    if not rest.startswith("="):
        raise Refused(3)
    return int(float(number.group())), rest[1:]


def startup_listing(lines: list[str]) -> list[str]:
    """The ``$N`` listing: ``$N0=...``, ``$N1=...``."""
    return [f"$N{index}={line}" for index, line in enumerate(lines)]


def _setting_text(number: int, value: float) -> str:
    if number in _INTEGER_SETTINGS or number in _ZERO_DECIMAL_SETTINGS:
        return f"{value:.0f}"
    return f"{value:.3f}"
