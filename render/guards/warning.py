"""A guard's warning, and the parts every guard shares: a lobe's width and the models' advice."""

from __future__ import annotations

import math
from dataclasses import dataclass

from render.engines.modes import HeldOutComparison

__all__ = [
    "RelightWarning",
    "lobe_width_deg",
    "model_advice",
]


@dataclass(frozen=True)
class RelightWarning:
    """One warning: a short code for programs and the sentence for people."""

    code: str
    message: str

    def __str__(self) -> str:
        return f"warning ({self.code}): {self.message}"


def lobe_width_deg(alpha: float) -> float:
    """Full width at half maximum of a GGX lobe of roughness ``alpha``, in light direction, deg.

    D(h) falls to half its peak at a half-vector angle t with cos^2 t = (alpha^2 sqrt 2 - 1) /
    (alpha^2 - 1); the reflected light direction turns twice as fast as the half vector, and the
    full width is twice the half width: 4 t.

    A closed form solved from D as :func:`core.brdf.ggx_distribution` defines it (tests hold
    D at t to half its peak), not a shading: there is no part of the shading sum to call here.
    """
    a2 = alpha * alpha
    if a2 >= 1.0 / math.sqrt(2.0):
        return 180.0  # no half maximum above the horizon: a broad lobe
    cos2 = (a2 * math.sqrt(2.0) - 1.0) / (a2 - 1.0)
    return 4.0 * math.degrees(math.acos(math.sqrt(cos2)))


def model_advice(comparison: HeldOutComparison | None, fix: str) -> str:
    """The advice of a guard that the per-sample models might cure, as the field measured it.

    Parameters
    ----------
    comparison : HeldOutComparison or None, the field's models against interpolation on
        held-out lights (None: not measured)
    fix : str, the cure that does not depend on the models (a denser capture, say)
    """
    if comparison is None:
        return (
            f"{fix}; the per-sample models (--scheme model) may do better: rig evaluate FIELD "
            "--split every-other measures whether they do"
        )
    if comparison.models_win:
        return f"relight through the per-sample models (--scheme model; {comparison}), or {fix}"
    return f"the per-sample models do not help here ({comparison}): {fix}"
