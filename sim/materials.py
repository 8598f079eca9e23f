"""The simulator's materials: parameters of the reflectance lobe of :mod:`core.brdf`.

A :class:`Material` is rho_d (diffuse albedo), F0 (constant specular reflectance) and the GGX
roughness alpha of ``f = rho_d / pi + F0 D G / (4 cos_i cos_o)``; the model itself, and how to
reproduce it in Mitsuba 3, is written out in :mod:`core.brdf`.
"""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import InputError

__all__ = ["Material"]


@dataclass(frozen=True)
class Material:
    """Parameters of the reflectance model (see the module docstring).

    Attributes
    ----------
    rho_d : (r, g, b), diffuse albedo in [0, 1]
    f0 : (r, g, b), specular reflectance in [0, 1]
    alpha : GGX roughness in (0, 1]
    """

    rho_d: tuple[float, float, float]
    f0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    alpha: float = 1.0

    def __post_init__(self) -> None:
        for name in ("rho_d", "f0"):
            value = getattr(self, name)
            if len(value) != 3 or not all(0.0 <= float(c) <= 1.0 for c in value):
                raise InputError(f"material {name} must be three values in [0, 1], got {value}")
        if not 0.0 < self.alpha <= 1.0:
            raise InputError(f"material alpha must be in (0, 1], got {self.alpha}")

    def to_json(self) -> dict[str, object]:
        """The material as plain JSON: ``rho_d``, ``f0`` and ``alpha``."""
        return {"rho_d": list(self.rho_d), "f0": list(self.f0), "alpha": self.alpha}
