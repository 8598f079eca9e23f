from __future__ import annotations

from pathlib import Path

import pytest

from core.sample_data import panorama_path, rti_capture_path


@pytest.fixture(scope="session")
def courtyard_path() -> Path:
    return panorama_path("courtyard")


@pytest.fixture(scope="session")
def studio_path() -> Path:
    return panorama_path("studio")


@pytest.fixture(scope="session")
def rti_lp_path() -> Path:
    """The bundled real RTI capture's .lp file (240 lights)."""
    return rti_capture_path()
