from __future__ import annotations

from pathlib import Path

import pytest

from core.sample_data import panorama_path


@pytest.fixture(scope="session")
def courtyard_path() -> Path:
    return panorama_path("courtyard")
