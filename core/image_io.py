"""Over 500 lines because it is the one module reading and writing every image format.

Image files: the one module that reads and writes EXR, Radiance HDR, PNG, JPEG, TIFF and TGA.

Readers return the stored values (:func:`read_pixels`: uint8, uint16 or float32, RGB channel
order, alpha dropped, grey kept as (H, W)) or linear float32 (:func:`read_linear`: integers
scaled to [0, 1] and decoded through a transfer curve). Every file is encoded in memory and
written by :func:`core.atomic.write_bytes_atomic`: checked (a full disk is an error, not a cut
file) and atomic (a file named by the project is never seen half-written, an earlier one stays
until the new one is complete).

Transfer curves. ``"srgb"`` and ``"linear"`` say how integers encode light; ``"auto"`` chooses
by the pixel type (:func:`auto_transfer`): 8-bit values are sRGB, 16-bit and float values are
linear (the convention of photographs developed from RAW and of RTI tools). The readers'
default stays ``"srgb"`` for 8 and 16 bits alike: it is what :func:`write_linear` writes into a
16-bit PNG (a display encoding), and panoramas are read that way.

================ ========================================= =====================================
format           read                                      write
================ ========================================= =====================================
OpenEXR          OpenEXR bindings, any compression (DWAB   float32 RGB or RGBA, ZIP
                 included); R, G, B or Y channels          (:func:`write_exr`)
Radiance .hdr    OpenCV, float32                           RGBE (:func:`write_linear`)
PNG              OpenCV, 8 or 16 bit                       8-bit sRGB (:func:`write_srgb8`),
                                                           8/16-bit sRGB of linear values
                                                           (:func:`write_linear`), lossless
                                                           frames (:func:`encode_lossless`),
                                                           8/16-bit data as given
                                                           (:func:`write_uint8`,
                                                           :func:`write_png16`)
JPEG             OpenCV; a file without its end-of-image   8-bit sRGB (:func:`write_srgb8`),
                 marker is refused (OpenCV would decode    8-bit data, 4:4:4 if asked
                 the truncated rest silently)              (:func:`write_uint8`)
TIFF             tifffile; strips past the end of the      16-bit linear RGB
                 file are refused                          (:func:`write_linear16_tiff`), float
                                                           frames (:func:`encode_lossless`)
TGA              Pillow: true colour, grey, colour-mapped, --
                 RLE, either origin; a truncated file is
                 refused, so is an RLE packet across
                 rows (TGA 1.0 allowed it, Pillow does
                 not read it)
BMP, WebP, JPEG  OpenCV, when built with the codec         --
2000, PNM, PFM,  (:data:`OPENCV_SUFFIXES` holds those
Sun raster, AVIF this OpenCV has)
================ ========================================= =====================================

OpenCV's own log lines about a broken file (``[ERROR:0@...]``) are caught and put into the
one-line error rather than printed before it.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import OpenEXR
import tifffile
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError

from core.atomic import write_bytes_atomic
from core.colour import linear_to_srgb, srgb_to_linear
from core.errors import InputError
from core.file_kinds import read_regular_bytes, special_file_problem

__all__ = [
    "EXR_SUFFIXES",
    "OPENCV_SUFFIXES",
    "READABLE_SUFFIXES",
    "TGA_SUFFIXES",
    "TIFF_SUFFIXES",
    "ImageFileError",
    "PixelDepth",
    "Transfer",
    "TransferChoice",
    "auto_transfer",
    "check_tiff_strips",
    "encode_lossless",
    "encode_picture",
    "linear_from_pixels",
    "pixel_depth",
    "read_linear",
    "read_pixels",
    "write_exr",
    "write_linear",
    "write_linear16_tiff",
    "write_png16",
    "write_srgb8",
    "write_uint8",
]

EXR_SUFFIXES = frozenset({".exr"})
TIFF_SUFFIXES = frozenset({".tif", ".tiff"})
#: Read through Pillow: OpenCV has no TGA codec.
TGA_SUFFIXES = frozenset({".tga"})
_JPEG_SUFFIXES = frozenset({".jpg", ".jpeg", ".jpe"})
#: Codecs an OpenCV build may leave out (GIF is not offered: animated, palette-only).
_OPENCV_OPTIONAL = (
    ".bmp", ".dib", ".webp", ".jp2", ".pbm", ".pgm", ".ppm", ".pnm", ".pfm", ".sr", ".ras",
    ".avif",
)  # fmt: skip
#: Read through OpenCV (Radiance HDR included), with the optional codecs this build has:
#: OpenCV registers each codec's reader and writer together, so the writer stands for both.
OPENCV_SUFFIXES = frozenset({".png", ".hdr", ".pic"} | _JPEG_SUFFIXES) | frozenset(
    suffix for suffix in _OPENCV_OPTIONAL if cv2.haveImageWriter(f"probe{suffix}")
)
READABLE_SUFFIXES = EXR_SUFFIXES | TIFF_SUFFIXES | TGA_SUFFIXES | OPENCV_SUFFIXES

#: How 8/16-bit values encode light: the sRGB curve, or proportional to it.
Transfer = Literal["srgb", "linear"]
#: A transfer as asked for: a curve, or ``"auto"`` to choose it by the pixel type.
TransferChoice = Literal["auto", "srgb", "linear"]
#: The kinds of stored values: 8-bit and 16-bit integers, or floats (any width).
PixelDepth = Literal["8-bit", "16-bit", "float"]

_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")


class ImageFileError(InputError):
    """An image file cannot be read (missing, unknown format, truncated, corrupt) or written."""


def read_pixels(path: str | os.PathLike[str]) -> NDArray[Any]:
    """The values an image file stores, in RGB order.

    Parameters
    ----------
    path : an image file with one of :data:`READABLE_SUFFIXES` (``.exr``, ``.hdr``, ``.png``,
        ``.jpg``, ``.tif``, ``.tga``, ``.bmp``...; any case)

    Returns
    -------
    ndarray, shape (H, W) for grey or (H, W, 3) for colour (alpha dropped, a colour map
    applied); uint8, uint16 or float (EXR, HDR and PFM: float32 linear; TIFF: as stored)

    Raises
    ------
    ImageFileError
        Missing, unknown format, truncated or corrupt; the message names the file.
    """
    file = Path(path)
    suffix = file.suffix.lower()
    if suffix not in READABLE_SUFFIXES:
        raise ImageFileError(
            f"{file}: unknown image format {suffix!r}; use one of {sorted(READABLE_SUFFIXES)}"
        )
    problem = special_file_problem(file)  # a FIFO would block the reader forever
    if problem is not None:
        raise ImageFileError(problem)
    if file.is_dir():
        raise ImageFileError(f"{file}: is a directory, not an image file")
    if not file.is_file():
        raise ImageFileError(f"{file}: no such file")
    if file.stat().st_size == 0:
        raise ImageFileError(f"{file}: the file is empty (0 bytes)")
    if suffix in EXR_SUFFIXES:
        return _read_exr(file)
    if suffix in TIFF_SUFFIXES:
        return _read_tiff(file)
    if suffix in TGA_SUFFIXES:
        return _read_tga(file)
    return _read_with_opencv(file)


def pixel_depth(pixels: NDArray[Any], *, where: str = "image") -> PixelDepth:
    """What stored values are: ``"8-bit"`` (uint8), ``"16-bit"`` (uint16) or ``"float"``.

    Raises
    ------
    ImageFileError
        Another pixel type; the message names ``where``.
    """
    if pixels.dtype == np.uint8:
        return "8-bit"
    if pixels.dtype == np.uint16:
        return "16-bit"
    if pixels.dtype in (np.float16, np.float32, np.float64):
        return "float"
    raise ImageFileError(f"{where}: unsupported pixel type {pixels.dtype}")


def auto_transfer(pixels: NDArray[Any], *, where: str = "image") -> Transfer:
    """The curve ``"auto"`` takes for stored values: 8-bit sRGB, 16-bit and float linear.

    Why: 8-bit files are display pictures (JPEG, most PNG, TGA, BMP), sRGB-encoded whatever
    their tags say; 16-bit PNG/TIFF photographs are developed from RAW without a curve so as
    to keep the sensor's proportionality (processing's decoder assumes the same); floats are
    always linear. A 16-bit file written for display (:func:`write_linear` writes sRGB) needs
    ``"srgb"`` said explicitly.
    """
    return "srgb" if pixel_depth(pixels, where=where) == "8-bit" else "linear"


def linear_from_pixels(
    pixels: NDArray[Any], *, transfer: TransferChoice = "srgb", where: str = "image"
) -> NDArray[np.float32]:
    """Stored values as linear float32: integers over their full scale, through ``transfer``.

    Parameters
    ----------
    pixels : ndarray of uint8, uint16 or float; any shape
    transfer : {"srgb", "linear", "auto"}
        The curve of integer values; ``"auto"`` takes :func:`auto_transfer`'s (8-bit sRGB,
        16-bit linear). Floats are linear as stored whatever is asked. The default decodes
        16-bit values as sRGB too (see the module docstring).
    where : str, named in the error for another pixel type or transfer

    Returns
    -------
    ndarray, same shape, float32 (1.0 = the integer format's full scale)
    """
    if transfer not in ("auto", "srgb", "linear"):
        raise InputError(f"{where}: transfer must be 'auto', 'srgb' or 'linear', not {transfer!r}")
    if transfer == "auto":
        transfer = auto_transfer(pixels, where=where)
    if pixels.dtype == np.uint8:
        values = pixels.astype(np.float32) / np.float32(255.0)
    elif pixels.dtype == np.uint16:
        values = pixels.astype(np.float32) / np.float32(65535.0)
    elif pixels.dtype in (np.float16, np.float32, np.float64):
        return np.ascontiguousarray(pixels, dtype=np.float32)
    else:
        raise ImageFileError(f"{where}: unsupported pixel type {pixels.dtype}")
    return srgb_to_linear(values) if transfer == "srgb" else values


def read_linear(
    path: str | os.PathLike[str], *, transfer: TransferChoice = "srgb"
) -> NDArray[np.float32]:
    """An image file as linear float32 (see :func:`read_pixels` and :func:`linear_from_pixels`).

    ``transfer`` applies to 8- and 16-bit files (``"auto"``: 8-bit sRGB, 16-bit linear); EXR,
    HDR, PFM and float TIFF are linear.
    """
    return linear_from_pixels(read_pixels(path), transfer=transfer, where=str(path))


def check_tiff_strips(path: str | os.PathLike[str]) -> None:
    """Refuse a TIFF-structured file (TIFF, DNG, NEF, CR2...) whose image data runs past its end.

    Decoders read the missing rows of a truncated uncompressed file as zeros without complaint,
    so the strip table is checked against the file size. Files that are not TIFF-structured
    pass unchecked.
    """
    file = Path(path)
    with open(file, "rb") as handle:
        magic = handle.read(4)
    if magic not in _TIFF_MAGIC:
        return
    size = file.stat().st_size
    try:
        with tifffile.TiffFile(file) as tiff:
            for page in tiff.pages:
                offsets = getattr(page, "dataoffsets", ())
                counts = getattr(page, "databytecounts", ())
                for offset, count in zip(offsets, counts, strict=False):
                    if offset + count > size:
                        raise ImageFileError(
                            f"{file}: truncated: image data ends at byte {offset + count}, the "
                            f"file has {size} bytes"
                        )
    except ImageFileError:
        raise
    except Exception as error:  # tifffile raises several types for broken structures
        raise ImageFileError(f"{file}: corrupt TIFF structure: {error}") from error


_LIBC = ctypes.CDLL(None)


@contextlib.contextmanager
def _library_output() -> Iterator[list[str]]:
    """Collect what C libraries write to the process's stderr (file descriptor 2) meanwhile.

    The OpenEXR library prints its own lines for a corrupt file before its exception (to
    stderr, and some warnings to stdout): they would precede the tool's one-line message. The
    lines of both are yielded (filled on exit) so the caller can put them in its error, or
    pass them on when the read succeeded.
    """
    lines: list[str] = []
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    said = io.StringIO()  # the bindings also write through Python's sys.stdout
    with tempfile.TemporaryFile() as sink:
        for fd in saved:
            os.dup2(sink.fileno(), fd)
        try:
            with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
                yield lines
        finally:
            # C++ streams write through C stdio, buffered when not a terminal: flush them
            # into the sink before the descriptors are restored.
            _LIBC.fflush(None)
            for fd, original in saved.items():
                os.dup2(original, fd)
                os.close(original)
            sink.seek(0)
            lines += sink.read().decode("utf-8", "replace").splitlines()
            lines += said.getvalue().splitlines()


#: Suffixes whose OpenCV codec cannot work in memory: it goes through a file of its own.
_THROUGH_A_FILE = (".hdr", ".pic")


@contextlib.contextmanager
def _opencv_scratch(suffix: str) -> Iterator[None]:
    """For ``suffix``'s codec, point OpenCV's temporary files into a folder removed on exit.

    The Radiance codec encodes and decodes through a file OpenCV names in the temp folder,
    and leaves that file behind when writing it fails (a full disk); so that nothing is left
    behind, the file is made in a folder of ours that goes whatever happens. OpenCV reads
    ``OPENCV_TEMP_PATH`` at every such file.
    """
    if suffix not in _THROUGH_A_FILE:
        yield
        return
    previous = os.environ.get("OPENCV_TEMP_PATH")
    with tempfile.TemporaryDirectory(prefix="rig-opencv-") as folder:
        os.environ["OPENCV_TEMP_PATH"] = folder
        try:
            yield
        finally:
            if previous is None:
                del os.environ["OPENCV_TEMP_PATH"]
            else:
                os.environ["OPENCV_TEMP_PATH"] = previous


def _read_exr(file: Path) -> NDArray[np.float32]:
    with _library_output() as printed:
        try:
            with OpenEXR.File(str(file), separate_channels=True) as exr:
                channels = {name: channel.pixels for name, channel in exr.channels().items()}
        except Exception as error:  # the bindings raise RuntimeError or ValueError, by case
            failure: Exception | None = error
        else:
            failure = None
    if failure is not None:
        said = "; ".join(line.strip() for line in printed[:2] if line.strip())
        raise ImageFileError(
            f"{file}: cannot read as OpenEXR (truncated or corrupt?): {failure}"
            + (f" ({said})" if said else "")
        ) from failure
    for line in printed:
        print(line, file=sys.stderr)
    names = {name.rsplit(".", 1)[-1]: name for name in channels}  # accept layer prefixes
    if all(c in names for c in "RGB"):
        planes = [channels[names[c]] for c in "RGB"]
    elif "Y" in names:
        planes = [channels[names["Y"]]] * 3
    else:
        raise ImageFileError(f"{file}: no R, G, B (or Y) channels, found {sorted(channels)}")
    return np.stack([np.asarray(p, dtype=np.float32) for p in planes], axis=-1)


def _read_tiff(file: Path) -> NDArray[Any]:
    check_tiff_strips(file)
    try:
        pixels = tifffile.imread(file)
    except Exception as error:  # tifffile raises several types for broken files
        raise ImageFileError(
            f"{file}: cannot decode as TIFF (truncated or corrupt?): {error}"
        ) from error
    pixels = np.asarray(pixels)
    if pixels.size == 0 or pixels.ndim not in (2, 3):
        # tifffile only logs a broken page table and returns nothing.
        raise ImageFileError(f"{file}: no image in the TIFF (corrupt page table?)")
    return pixels[:, :, :3] if pixels.ndim == 3 and pixels.shape[2] == 4 else pixels


def _read_tga(file: Path) -> NDArray[np.uint8]:
    try:
        # formats=["TGA"]: a PNG renamed .tga is refused, as OpenCV refuses one renamed .jpg.
        with Image.open(file, formats=["TGA"]) as opened:
            opened.load()  # decodes now: a truncated file raises here, not later
            picture: Image.Image = opened
            if picture.mode in ("P", "PA"):
                picture = picture.convert("RGB")  # the colour map applied, alpha dropped
            mode = picture.mode
            pixels = np.asarray(picture)
    except (OSError, UnidentifiedImageError, SyntaxError, ValueError) as error:
        # Pillow raises OSError for truncated data, UnidentifiedImageError for a bad header.
        hint = ""
        if "overrun" in str(error):
            hint = (
                "; if it is run-length encoded, an RLE packet runs across rows (TGA 1.0 "
                "allowed it, 2.0 does not): save it again uncompressed or per row"
            )
        raise ImageFileError(
            f"{file}: cannot decode as TGA (truncated or corrupt?): {error}{hint}"
        ) from error
    if pixels.dtype != np.uint8 or mode not in ("L", "LA", "RGB", "RGBA"):
        raise ImageFileError(f"{file}: unsupported TGA pixel layout {mode!r} ({pixels.dtype})")
    if mode == "LA":
        return np.ascontiguousarray(pixels[:, :, 0])
    return np.ascontiguousarray(pixels[:, :, :3]) if mode == "RGBA" else pixels


def _read_with_opencv(file: Path) -> NDArray[Any]:
    data = read_regular_bytes(file)
    suffix = file.suffix.lower()
    # OpenCV decodes a truncated JPEG without complaint; the end-of-image marker tells.
    if suffix in _JPEG_SUFFIXES and data.rfind(b"\xff\xd9", max(0, len(data) - 4096)) < 0:
        raise ImageFileError(f"{file}: JPEG has no end-of-image marker (file truncated?)")
    with _library_output() as printed, _opencv_scratch(suffix):
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        said = _opencv_said(printed)
        raise ImageFileError(
            f"{file}: cannot decode as {suffix[1:].upper()} (truncated or corrupt?)"
            + (f" ({said})" if said else "")
        )
    for line in printed:
        print(line, file=sys.stderr)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGRA2RGB if image.shape[2] == 4 else cv2.COLOR_BGR2RGB
        image = cv2.cvtColor(image, code)
    return np.asarray(image)


def _opencv_said(lines: list[str]) -> str:
    """The gist of OpenCV's log lines: the text after its ``error:`` markers, at most two."""
    said = []
    for line in lines:
        text = line.strip()
        if not text:
            continue
        said.append(text.rsplit("error:", 1)[-1].strip() if "error:" in text else text)
    return "; ".join(said[:2])


def _check_picture(path: Path, picture: NDArray[Any], dtype: type[np.generic]) -> None:
    if picture.ndim != 3 or picture.shape[2] != 3 or picture.dtype != dtype:
        raise ImageFileError(
            f"{path}: expected an (H, W, 3) {np.dtype(dtype).name} picture, got "
            f"{picture.shape} {picture.dtype}"
        )


def _imwrite(path: Path, bgr: NDArray[Any], params: list[int] | None = None) -> None:
    """Encode ``bgr`` by ``path``'s suffix in memory and write the bytes, checked and atomic.

    Not ``cv2.imwrite``: it reports success on a full disk, leaving a cut or empty file.
    """
    suffix = path.suffix.lower()
    with _library_output() as printed, _opencv_scratch(suffix):
        ok, encoded = cv2.imencode(suffix, np.ascontiguousarray(bgr), params or [])
    if not ok:  # some codecs (Radiance) encode through a temporary file: a full disk fails here
        said = _opencv_said(printed)
        raise ImageFileError(
            f"{path}: cannot write: OpenCV could not encode the image"
            + (f" ({said})" if said else "")
            + "; is the disk full? Nothing was replaced"
        )
    for line in printed:
        print(line, file=sys.stderr)
    write_bytes_atomic(path, encoded.tobytes())


def write_exr(
    path: str | os.PathLike[str],
    rgb: NDArray[np.floating],
    alpha: NDArray[np.floating] | None = None,
) -> None:
    """Write linear RGB (H, W, 3), and alpha (H, W) when given, as float32 OpenEXR (ZIP)."""
    image = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32)[:, :, :3])
    channels = {"RGB": image}
    if alpha is not None:
        coverage = np.ascontiguousarray(np.asarray(alpha, dtype=np.float32))
        if coverage.shape != image.shape[:2]:
            raise ImageFileError(
                f"{path}: alpha {coverage.shape} does not match the image {image.shape}"
            )
        channels["A"] = coverage
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    buffer = io.BytesIO()
    with OpenEXR.File(header, channels) as exr:
        exr.write(buffer)  # in memory: the file itself is written checked
    write_bytes_atomic(path, buffer.getvalue())


def write_linear(
    path: str | os.PathLike[str], rgb: NDArray[np.floating], *, bits: Literal[8, 16] = 8
) -> None:
    """Write linear RGB (H, W, 3) by suffix.

    ``.exr``: float32 RGB, ZIP-compressed. ``.hdr``/``.pic``: Radiance RGBE. ``.png``:
    sRGB-encoded, clipped to [0, 1], with ``bits`` per channel (tone-map first for display).
    """
    file = Path(path)
    image = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32)[:, :, :3])
    suffix = file.suffix.lower()
    if suffix == ".exr":
        write_exr(file, image)
        return
    if suffix not in (".hdr", ".pic", ".png"):
        raise ImageFileError(f"{file}: cannot write {suffix!r}; use .exr, .hdr or .png")
    if not np.isfinite(image).all():
        raise ImageFileError(f"{file}: the image holds NaN or infinite values; nothing written")
    if suffix == ".png":
        scale = 255.0 if bits == 8 else 65535.0
        encoded = np.round(linear_to_srgb(image) * scale)
        _imwrite(file, encoded.astype(np.uint8 if bits == 8 else np.uint16)[:, :, ::-1])
    else:
        _imwrite(file, image[:, :, ::-1])


def write_srgb8(
    path: str | os.PathLike[str], picture: NDArray[np.uint8], quality: int = 95
) -> None:
    """Write an (H, W, 3) uint8 sRGB picture as PNG or JPEG (by suffix, ``quality`` for JPEG)."""
    write_uint8(path, picture, quality=quality)


def write_uint8(
    path: str | os.PathLike[str],
    picture: NDArray[np.uint8],
    *,
    quality: int = 95,
    full_chroma: bool = False,
) -> None:
    """Write (H, W, 3) uint8 values as PNG or JPEG (by suffix), channel for channel.

    The values are written as given, whatever they encode (an sRGB picture, or data such as
    the quantised coefficient planes of :mod:`render.web_export`).

    Parameters
    ----------
    path : a ``.png``, ``.jpg`` or ``.jpeg`` file
    picture : ndarray, shape (H, W, 3), uint8, RGB order
    quality : int, JPEG quality 0..100 (PNG is lossless)
    full_chroma : bool
        JPEG: keep the colour channels at full resolution (4:4:4 sampling) rather than the
        usual 4:2:0; for data whose three channels are unrelated, as planes of coefficients.
    """
    target = Path(path)
    _check_picture(target, picture, np.uint8)
    suffix = target.suffix.lower()
    if suffix not in {".png", ".jpg", ".jpeg"}:
        raise ImageFileError(
            f"{target}: an 8-bit picture is written as .png or .jpg, not {suffix!r}"
        )
    params: list[int] = []
    if suffix != ".png":
        params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
        if full_chroma:
            params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    _imwrite(target, picture[:, :, ::-1], params)


def write_png16(path: str | os.PathLike[str], picture: NDArray[np.uint16]) -> None:
    """Write (H, W, 3) uint16 values as a 16-bit PNG, as given (no transfer curve applied).

    For data such as normal maps; linear images for display go through :func:`write_linear`.
    """
    target = Path(path)
    _check_picture(target, picture, np.uint16)
    if target.suffix.lower() != ".png":
        raise ImageFileError(f"{target}: 16-bit values are written as .png, not {target.suffix!r}")
    _imwrite(target, picture[:, :, ::-1])


def write_linear16_tiff(path: str | os.PathLike[str], picture: NDArray[np.uint16]) -> None:
    """Write an (H, W, 3) uint16 linear RGB picture as an uncompressed TIFF."""
    target = Path(path)
    _check_picture(target, picture, np.uint16)
    buffer = io.BytesIO()
    tifffile.imwrite(buffer, picture, photometric="rgb", metadata=None)
    write_bytes_atomic(target, buffer.getvalue())


def encode_picture(
    picture: NDArray[np.uint8], suffix: str, *, quality: int = 95
) -> tuple[str, bytes]:
    """``(suffix, bytes)`` of an 8-bit RGB (or grey) picture as a ``.jpg`` or ``.png`` file.

    For pictures sent rather than stored (the viewer's frames); ``quality`` is JPEG's, 1-100.
    """
    if picture.dtype != np.uint8 or picture.ndim not in (2, 3):
        raise ImageFileError(
            f"a picture must be (H, W[, 3]) uint8, got {picture.shape} {picture.dtype}"
        )
    suffix = suffix.lower()
    if suffix not in (".jpg", ".png"):
        raise ImageFileError(f"pictures are encoded as .jpg or .png, not {suffix}")
    image = picture[:, :, ::-1] if picture.ndim == 3 else picture  # OpenCV writes BGR
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if suffix == ".jpg" else []
    ok, encoded = cv2.imencode(suffix, np.ascontiguousarray(image), params)
    if not ok:
        raise ImageFileError(f"could not encode a {picture.shape} picture as {suffix}")
    return suffix, encoded.tobytes()


def encode_lossless(pixels: NDArray[Any]) -> tuple[str, bytes]:
    """``(suffix, bytes)`` of a lossless file of RGB (or grey) pixels.

    uint8 and uint16 become PNG (deterministic: the same pixels give the same bytes), floats a
    float32 TIFF.
    """
    if pixels.dtype in (np.uint8, np.uint16):
        image = pixels[:, :, ::-1] if pixels.ndim == 3 else pixels  # OpenCV writes BGR
        ok, encoded = cv2.imencode(".png", np.ascontiguousarray(image))
        if not ok:
            raise ImageFileError(f"could not encode {pixels.shape} {pixels.dtype} pixels as PNG")
        return ".png", encoded.tobytes()
    if pixels.dtype.kind == "f":
        buffer = io.BytesIO()
        colour = pixels.ndim == 3 and pixels.shape[2] == 3
        photometric = "rgb" if colour else "minisblack"
        tifffile.imwrite(buffer, np.asarray(pixels, dtype=np.float32), photometric=photometric)
        return ".tif", buffer.getvalue()
    raise ImageFileError(f"pixels of dtype {pixels.dtype} cannot be stored; use uint8/16 or float")
