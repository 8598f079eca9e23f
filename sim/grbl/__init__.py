"""The emulated GRBL 1.1 gantry controller: a pty the real ``pyserial`` talks to, and its parts.

The emulator (:mod:`sim.grbl.emulator`) serves the pseudo-terminal; below it the machine's lines
(:mod:`sim.grbl.machine`), states (:mod:`sim.grbl.states`), motion, G-code subset, arcs,
settings, limit switches, spindle, status report, line filter and words, each as GRBL's own
source files have them. See ``docs/grbl.md``.
"""

from __future__ import annotations
