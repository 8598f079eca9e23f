"""The emulated Dynamixel Protocol 2.0 servo chain: a pty the real ``dynamixel_sdk`` talks to.

The chain (:mod:`sim.dynamixel.emulator`), one X-series servo's control table and state
(:mod:`sim.dynamixel.servo`), its trapezoidal moves (:mod:`sim.dynamixel.motion`), the wire
format (:mod:`sim.dynamixel.protocol`) and fault injection (:mod:`sim.dynamixel.faults`). See
``docs/dynamixel.md``.
"""

from __future__ import annotations
