from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import settings

from core.sample_data import panorama_path

# No test is timed (a loaded 2-core machine, numba compiling on a first call): hypothesis'
# per-example deadline would turn load into failures.
settings.register_profile("untimed", deadline=None)
settings.load_profile("untimed")


@pytest.fixture(scope="session")
def courtyard_path() -> Path:
    return panorama_path("courtyard")
