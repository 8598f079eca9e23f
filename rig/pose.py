"""The rig's pose: where the camera arm, the light gantry and the turntable stand, in degrees.

The five axis roles are fixed names used by the config (``[axes.<role>]``), the safety checks,
the drivers and the sweep plans. Angles are rig angles in the conventions of
``docs/conventions.md`` (azimuth counter-clockwise from ``+x``, inclination from ``+z``), as the
axis reports them: no wrapping, so a servo at 370 degrees is at 370, not 10.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from core.errors import InputError

__all__ = ["CAMERA_ROLES", "LIGHT_ROLES", "OPTIONAL_ROLES", "REQUIRED_ROLES", "ROLES", "RigPose"]

#: Axis roles every rig has.
REQUIRED_ROLES = ("camera_azimuth", "camera_inclination", "light_azimuth", "light_inclination")
#: Axis roles a rig may have.
OPTIONAL_ROLES = ("turntable",)
ROLES = REQUIRED_ROLES + OPTIONAL_ROLES
CAMERA_ROLES = ("camera_azimuth", "camera_inclination")
LIGHT_ROLES = ("light_azimuth", "light_inclination")


@dataclass(frozen=True)
class RigPose:
    """A pose of the whole rig, degrees.

    Attributes
    ----------
    camera_azimuth_deg, camera_inclination_deg : float
        Direction from the object toward the camera.
    light_azimuth_deg, light_inclination_deg : float
        Direction from the object toward the light.
    turntable_deg : float
        Rotation of the object about ``+z`` (counter-clockwise seen from above); 0 on a rig
        without a turntable.
    """

    camera_azimuth_deg: float
    camera_inclination_deg: float
    light_azimuth_deg: float
    light_inclination_deg: float
    turntable_deg: float = 0.0

    def __post_init__(self) -> None:
        for role, value in self.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError(f"pose {role}_deg must be a number, got {value!r}")
            if not math.isfinite(value):
                raise InputError(f"pose {role}_deg must be finite, got {value}")

    def items(self) -> tuple[tuple[str, float], ...]:
        """``(role, degrees)`` pairs in :data:`ROLES` order."""
        return tuple((role, self.get(role)) for role in ROLES)

    def get(self, role: str) -> float:
        """The angle of axis ``role`` in degrees."""
        if role not in ROLES:
            raise InputError(f"unknown axis role {role!r}; roles are {', '.join(ROLES)}")
        return float(getattr(self, f"{role}_deg"))

    def to_dict(self) -> dict[str, float]:
        """``{"<role>_deg": degrees}``, the form configs and manifests store."""
        return {f"{role}_deg": value for role, value in self.items()}

    @classmethod
    def from_roles(cls, degrees: Mapping[str, float]) -> RigPose:
        """Build a pose from ``{role: degrees}`` (turntable optional)."""
        unknown = set(degrees) - set(ROLES)
        if unknown:
            raise InputError(
                f"unknown axis role(s) {', '.join(sorted(unknown))}; roles are {', '.join(ROLES)}"
            )
        missing = [role for role in REQUIRED_ROLES if role not in degrees]
        if missing:
            raise InputError(f"pose is missing {', '.join(missing)}")
        return cls(**{f"{role}_deg": value for role, value in degrees.items()})

    def interpolate(self, other: RigPose, fraction: float) -> RigPose:
        """The pose ``fraction`` of the way along a straight move (every axis linear) to other."""
        return RigPose.from_roles(
            {
                role: start + fraction * (end - start)
                for (role, start), (_, end) in zip(self.items(), other.items(), strict=True)
            }
        )
