"""The sample data shipped inside the package: two HDR panoramas and a real RTI capture.

Tests, the demo and the benchmarks read them through these functions, so a clone of the
repository needs nothing beside it. Licences and attribution: ``core/data/*/README.md``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Literal, get_args

from core.errors import InputError

__all__ = ["PANORAMA_NAMES", "PanoramaName", "panorama_path", "rti_capture_path"]

PanoramaName = Literal["courtyard", "studio"]
#: The bundled panoramas (``core/data/panoramas/README.md``).
PANORAMA_NAMES: tuple[PanoramaName, ...] = get_args(PanoramaName)


def _data() -> Path:
    return Path(str(resources.files("core") / "data"))


def panorama_path(name: PanoramaName = "courtyard") -> Path:
    """Path of a bundled equirectangular HDR panorama (1024 x 512 OpenEXR, CC0).

    Parameters
    ----------
    name : {"courtyard", "studio"}
        The daylit courtyard (moderate dynamic range) or the studio with two lamps (most of
        the energy in 1 % of the pixels).
    """
    if name not in PANORAMA_NAMES:
        raise InputError(f"no bundled panorama {name!r}; use one of {', '.join(PANORAMA_NAMES)}")
    return _data() / "panoramas" / f"{name}.exr"


def rti_capture_path() -> Path:
    """The ``.lp`` file of the bundled real RTI capture (240 lights, one 64 x 43 view, MIT)."""
    return _data() / "rti" / "loewenkopf" / "dirs.lp"
