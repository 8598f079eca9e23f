from __future__ import annotations

import pytest

from core.errors import InputError
from sim.materials import Material


def test_invalid_materials() -> None:
    with pytest.raises(InputError, match="alpha"):
        Material(rho_d=(0.5, 0.5, 0.5), alpha=0.0)
    with pytest.raises(InputError, match="rho_d"):
        Material(rho_d=(1.5, 0.5, 0.5))
