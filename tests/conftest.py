from __future__ import annotations

from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
PANORAMAS = SHARED / "panoramas"


@pytest.fixture(scope="session")
def courtyard_path() -> Path:
    return PANORAMAS / "courtyard.exr"


@pytest.fixture(scope="session")
def studio_path() -> Path:
    return PANORAMAS / "studio.exr"
