"""GRBL 1.1's real-time status report: its fields and when ``WCO`` and ``Ov``/``A`` appear.

Its fields are formatted as ``report.c`` does; counters decide when ``WCO`` and ``Ov``/``A`` are
included.

WCO comes in the first report after a reset or an offset change and then every 10 (idle) or 30
(busy) reports; Ov every 10 (idle) or 20 (busy) reports and in the first after a spindle or
coolant change, but never in the same report as WCO (it moves to the next one), and with it ``A``
when the spindle or coolant is on.
"""

from __future__ import annotations

from sim.grbl_motion import Vec

__all__ = ["StatusReporter", "axes_text"]


def axes_text(values: Vec) -> str:
    """Three coordinates as GRBL prints them: ``x,y,z`` with 3 decimals, never ``-0.000``."""
    return ",".join("0.000" if f"{v:.3f}" == "-0.000" else f"{v:.3f}" for v in values)


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
        spindle : 3 CW, 4 CCW, 5 off
        spindle_speed : the spindle's speed while on
        flood, mist : coolant
        pins : the ``Pn`` field, empty for none
        """
        if not mask & 1:
            position = (position[0] - wco[0], position[1] - wco[1], position[2] - wco[2])
        parts = [state, ("MPos:" if mask & 1 else "WPos:") + axes_text(position)]
        if mask & 2:
            parts.append(f"Bf:{buffers[0]},{buffers[1]}")
        speed = spindle_speed if spindle != 5 else 0.0
        parts.append(f"FS:{feed:.0f},{speed:.0f}")
        if pins:
            parts.append(f"Pn:{pins}")
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = 29 if busy else 9
            self._ovr_counter = self._ovr_counter or 1
            parts.append("WCO:" + axes_text(wco))
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
