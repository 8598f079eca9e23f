"""The path-traced worlds: meshes with any Mitsuba 3 BSDF, their fields and ground truth.

:mod:`sim.world.mitsuba` renders a world's reflectance field, its ground truth under a panorama
and their noise; :mod:`sim.world.rti` its RTI dome captures. The parts: world files
(:mod:`sim.world.files`; the bundled ones are the TOML files in ``sim/worlds/``), shapes,
meshes, materials, textures, the Mitsuba scenes and passes (:mod:`sim.world.render`), surface
samples and visibility. See ``docs/world.md``.
"""

from __future__ import annotations
