"""Float planes kept on disk while a view is fitted, a band of pixels at a time.

A plane's 8-bit quantisation needs its range over every pixel before any byte is written,
and a 24-megapixel view's PTM and HSH coefficients are gigabytes of floats. So each band's
values go to a temporary file, image by image, the ranges are kept as they come, and each
image of three planes is read back alone to be quantised and written: memory holds one band
and one image, not the view.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

__all__ = ["MIN_SPAN", "PlaneStore", "quantise"]

#: Smallest plane range written: a constant plane still has a finite bias.
MIN_SPAN = 1e-6
#: Values (rows of a plane image) quantised at once.
QUANTISE_ROWS = 1 << 20


class PlaneStore:
    """J images of three planes over P pixels, (J, P, 3) float32, in a temporary file.

    Parameters
    ----------
    folder : Path, where the temporary file is made (removed by :meth:`close`)
    images : int, J
    pixels : int, P
    """

    def __init__(self, folder: Path, images: int, pixels: int) -> None:
        self.images = images
        self.pixels = pixels
        handle, name = tempfile.mkstemp(prefix=".planes-", suffix=".f32", dir=folder)
        os.close(handle)
        self.path = Path(name)
        self._file = open(self.path, "w+b")  # closed by close()
        self._file.truncate(images * pixels * 12)
        #: Least and greatest value of each plane (J, 3) so far.
        self.low = np.full((images, 3), np.inf)
        self.high = np.full((images, 3), -np.inf)

    def write(self, start: int, values: NDArray[np.floating]) -> None:
        """Store pixels ``start .. start + n``: values (n, J, 3)."""
        v = np.asarray(values, dtype=np.float32)
        if not len(v):
            return
        for j in range(self.images):
            self._file.seek((j * self.pixels + start) * 12)
            self._file.write(np.ascontiguousarray(v[:, j]).tobytes())
        self.low = np.minimum(self.low, v.min(axis=0))
        self.high = np.maximum(self.high, v.max(axis=0))

    def image(self, j: int) -> NDArray[np.float32]:
        """Image ``j``'s values (P, 3) float32."""
        self._file.flush()
        self._file.seek(j * self.pixels * 12)
        data = np.fromfile(self._file, dtype=np.float32, count=self.pixels * 3)
        return data.reshape(self.pixels, 3)

    def ranges(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(low, span) per plane (J, 3) of the values written (none written: 0 and 1)."""
        low = np.where(np.isfinite(self.low), self.low, 0.0)
        high = np.where(np.isfinite(self.high), self.high, 1.0)
        return low, np.maximum(high - low, MIN_SPAN)

    def close(self) -> None:
        """Remove the file."""
        self._file.close()
        self.path.unlink(missing_ok=True)

    def __enter__(self) -> PlaneStore:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


def quantise(
    values: NDArray[np.floating], low: NDArray[np.floating], span: NDArray[np.floating]
) -> NDArray[np.uint8]:
    """The nearest of 256 levels of each value: ``round((v - low) / span * 255)``, clipped.

    A viewer decodes ``byte / 255 * span + low``: each value errs by ``span / 510`` at most.
    Computed :data:`QUANTISE_ROWS` rows at a time: the float64 temporaries of a whole plane
    image of a 24-megapixel view would be gigabytes.
    """
    v = np.asarray(values)
    out = np.empty(v.shape, dtype=np.uint8)
    for start in range(0, len(v), QUANTISE_ROWS):
        part = slice(start, start + QUANTISE_ROWS)
        scaled = (v[part].astype(np.float64) - low) / span * 255.0
        out[part] = np.clip(np.rint(scaled), 0, 255)
    return out
