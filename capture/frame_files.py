"""A captured frame as the bytes of an image file (what the dataset stores).

Pixels in memory become lossless files: 16-bit linear PNG for ``uint16`` (cameras and the
simulated rig's ``linear16`` output), 8-bit PNG for ``uint8``, float32 TIFF for float data. A
frame the camera already wrote to disk (a DSLR's RAW, a simulated DNG) is stored as is. PNG
encoding is deterministic, so a simulated capture repeated gives byte-identical pixels' files;
the dataset then writes the image's identity into each PNG (``capture.image_identity``), which
names its own dataset.
"""

from __future__ import annotations

from core.image_io import encode_lossless
from rig.devices import Frame

__all__ = ["frame_file"]


def frame_file(frame: Frame) -> tuple[str, bytes]:
    """``(suffix, bytes)`` of the file that stores ``frame``."""
    if frame.path is not None:
        return frame.path.suffix.lower(), frame.path.read_bytes()
    assert frame.pixels is not None  # a Frame has pixels or a path
    return encode_lossless(frame.pixels)
