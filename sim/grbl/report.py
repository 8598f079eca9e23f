"""GRBL 1.1's real-time status report: its fields and when ``WCO`` and ``Ov``/``A`` appear.

Its fields are formatted as ``report.c`` does; counters decide when ``WCO`` and ``Ov``/``A`` are
included. With ``$13=1`` positions and offsets are reported in inches with 4 decimals and the
feed in inch/min with 1 decimal (``printFloat_CoordValue``/``printFloat_RateValue``); the
machine keeps millimetres. The ``$#`` listing (:func:`ngc_parameter_lines`) follows the same rule.

WCO comes in the first report after a reset or an offset change and then every 10 (idle) or 30
(busy) reports; Ov every 10 (idle) or 20 (busy) reports and in the first after a spindle or
coolant change, but never in the same report as WCO (it moves to the next one), and with it ``A``
when the spindle or coolant is on.
"""

from __future__ import annotations

from sim.grbl.motion import Vec

__all__ = ["StatusReporter", "axes_text", "ngc_parameter_lines"]

_MM_PER_INCH = 25.4


def axes_text(values: Vec, *, inches: bool = False) -> str:
    """Three coordinates as GRBL prints them: ``x,y,z`` with 3 decimals (4 in inches).

    Never ``-0.000``.
    """
    if inches:
        values = (values[0] / _MM_PER_INCH, values[1] / _MM_PER_INCH, values[2] / _MM_PER_INCH)
    digits = 4 if inches else 3
    texts = [f"{v:.{digits}f}" for v in values]
    return ",".join(t[1:] if t.startswith("-") and not t.strip("-0.") else t for t in texts)


def ngc_parameter_lines(g92: Vec, *, inches: bool = False) -> list[str]:
    """The ``$#`` listing: G54-G59, G28, G30 (all zero here), G92, TLO and PRB."""
    zero = axes_text((0.0, 0.0, 0.0), inches=inches)
    names = ("G54", "G55", "G56", "G57", "G58", "G59", "G28", "G30")
    return [
        *(f"[{name}:{zero}]" for name in names),
        f"[G92:{axes_text(g92, inches=inches)}]",
        f"[TLO:{'0.0000' if inches else '0.000'}]",
        f"[PRB:{zero}:0]",
    ]


class StatusReporter:
    """Formats ``<...>`` status reports and keeps GRBL's WCO and override refresh counters."""

    def __init__(self) -> None:
        self._wco_counter = 0
        self._ovr_counter = 0

    def refresh_offsets(self) -> None:
        """Show ``WCO`` in the next report (the work offset changed)."""
        self._wco_counter = 0

    def refresh_overrides(self) -> None:
        """Show ``Ov`` (and ``A``) in the next report (spindle or coolant switched)."""
        self._ovr_counter = 0

    def report(
        self,
        *,
        state: str,
        busy: bool,
        mask: int,
        position: Vec,
        wco: Vec,
        buffers: tuple[int, int],
        feed: float,
        spindle: int,
        spindle_speed: float,
        flood: bool,
        mist: bool,
        pins: str,
        inches: bool = False,
    ) -> str:
        """One status report; counts it against the refresh counters.

        Parameters
        ----------
        state : the state as reported (``Idle``, ``Run``, ``Hold:0``, ...)
        busy : True while moving, holding or homing (the counters' longer periods)
        mask : ``$10``: bit 0 machine (else work) position, bit 1 the ``Bf`` field
        position : machine position, units
        wco : work coordinate offset, units
        buffers : (free planner blocks, free receive-buffer bytes)
        feed : current feed rate, units/min
        spindle : the output: 3 CW, 4 CCW, 5 when the PWM is off
        spindle_speed : the speed the output runs at (``sys.spindle_speed``)
        flood, mist : coolant
        pins : the ``Pn`` field, empty for none
        inches : ``$13=1``: report in inches
        """
        if not mask & 1:
            position = (position[0] - wco[0], position[1] - wco[1], position[2] - wco[2])
        parts = [state, ("MPos:" if mask & 1 else "WPos:") + axes_text(position, inches=inches)]
        if mask & 2:
            parts.append(f"Bf:{buffers[0]},{buffers[1]}")
        rate = f"{feed / _MM_PER_INCH:.1f}" if inches else f"{feed:.0f}"
        parts.append(f"FS:{rate},{spindle_speed:.0f}")
        if pins:
            parts.append(f"Pn:{pins}")
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = 29 if busy else 9
            self._ovr_counter = self._ovr_counter or 1
            parts.append("WCO:" + axes_text(wco, inches=inches))
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = 19 if busy else 9
            parts.append("Ov:100,100,100")
            accessories = ("S" if spindle == 3 else "C" if spindle == 4 else "") + (
                ("F" if flood else "") + ("M" if mist else "")
            )
            if accessories:
                parts.append(f"A:{accessories}")
        return "<" + "|".join(parts) + ">"
