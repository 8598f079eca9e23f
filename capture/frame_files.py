"""A captured frame as the bytes of an image file (what the dataset stores).

Pixels in memory become lossless files: 16-bit linear PNG for ``uint16`` (cameras and the
simulated rig's ``linear16`` output), 8-bit PNG for ``uint8``, float32 TIFF for float data. A
frame the camera already wrote to disk (a DSLR's RAW, a simulated DNG) is stored as is. PNG
encoding is deterministic, so a simulated capture repeated gives byte-identical files.
"""

from __future__ import annotations

import io

import cv2
import numpy as np
import tifffile

from core.errors import InputError
from rig.devices import Frame

__all__ = ["frame_file"]


def frame_file(frame: Frame) -> tuple[str, bytes]:
    """``(suffix, bytes)`` of the file that stores ``frame``."""
    if frame.path is not None:
        return frame.path.suffix.lower(), frame.path.read_bytes()
    pixels = frame.pixels
    assert pixels is not None  # a Frame has pixels or a path
    if pixels.dtype in (np.uint8, np.uint16):
        # OpenCV writes BGR; frames are RGB by contract.
        image = pixels[:, :, ::-1] if pixels.ndim == 3 else pixels
        ok, encoded = cv2.imencode(".png", np.ascontiguousarray(image))
        if not ok:
            raise InputError(f"could not encode a {pixels.shape} {pixels.dtype} frame as PNG")
        return ".png", encoded.tobytes()
    if pixels.dtype.kind == "f":
        buffer = io.BytesIO()
        tifffile.imwrite(buffer, np.asarray(pixels, dtype=np.float32))
        return ".tif", buffer.getvalue()
    raise InputError(f"frames of dtype {pixels.dtype} cannot be stored; use uint8/16 or float")
