"""The simulator's calibration scenes, rendered per pixel by ray casting.

Three targets, each seen by a :class:`core.camera_model.PinholeCamera` (optionally through a lens
with radial distortion, OpenCV's ``k1, k2`` model) and returned as linear float32 radiance
``(H, W, 3)``:

- a ChArUco board (texture from OpenCV's ``board.generateImage``) on a plane of any pose: flat at
  the object's place for extrinsics, tilted and shifted for intrinsics (:func:`render_charuco`);
- a mirror sphere (chrome ball) reflecting one small bright disc light and a dim environment, so
  its highlight can be found as RTI tools find it (:func:`render_mirror_sphere`);
- a flat white Lambertian target of known albedo under a directional or point light, for light
  intensity and the 1/r^2 falloff (:func:`render_white_target`).

Rays are cast through every pixel analytically (no point clouds), so edges are crisp; pixels
whose neighbourhood is not uniform are supersampled (box filter, as a sensor pixel integrates).
:func:`record` passes radiance through the sensor model to 16-bit linear or 8-bit sRGB pixels.

Pixel convention (``core.camera_model``): pixel (row i, col j) covers [j, j + 1) x [i, i + 1) in
continuous (col, row) coordinates, principal point at (W / 2, H / 2). Distortion acts on the
normalised coordinates of OpenCV's camera frame (x right, y down): a ray of undistorted
normalised coordinates (x, y) lands at ``(x, y) (1 + k1 r^2 + k2 r^4)``, r^2 = x^2 + y^2.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.camera_model import PinholeCamera
from core.directions import normalize
from core.errors import InputError
from sim.sensor import Sensor, expose, to_linear16, to_srgb8

__all__ = [
    "BoardPlacement",
    "DiscLight",
    "LensDistortion",
    "WhiteTarget",
    "record",
    "render_charuco",
    "render_mirror_sphere",
    "render_white_target",
]

F64 = NDArray[np.float64]
#: Shader: ray origin (3,) and unit directions (N, 3) to radiance (N, 3).
Shader = Callable[[F64, F64], F64]

#: Board texels per chessboard square: fine enough that nearest-texel lookup is exact at the
#: pixel scale, small enough to generate in a few milliseconds.
TEXELS_PER_SQUARE = 96
#: White border around the printed board, in squares, so the outer black squares have an edge.
BOARD_MARGIN_SQUARES = 0.5
ROWS_PER_CHUNK = 64
#: Relative change across a 3 x 3 neighbourhood that marks a pixel for supersampling.
EDGE_CONTRAST = 0.02
#: Board axes (columns) of a board lying face up, its printed image upright seen from above.
FLAT_BOARD = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))


@dataclass(frozen=True)
class LensDistortion:
    """Radial lens distortion, OpenCV's ``k1, k2`` (no tangential terms, ``k3 = 0``)."""

    k1: float = 0.0
    k2: float = 0.0

    def undistort(self, x: F64, y: F64) -> tuple[F64, F64]:
        """Undistorted normalised coordinates of distorted ones (Newton's method on the radius)."""
        if self.k1 == 0.0 and self.k2 == 0.0:
            return x, y
        distorted = np.hypot(x, y)
        r = distorted.copy()
        for _ in range(30):
            r2 = r * r
            error = r * (1.0 + self.k1 * r2 + self.k2 * r2 * r2) - distorted
            if np.abs(error).max() < 1e-13:
                scale = np.divide(r, distorted, out=np.ones_like(r), where=distorted > 0)
                return x * scale, y * scale
            r = r - error / (1.0 + 3.0 * self.k1 * r2 + 5.0 * self.k2 * r2 * r2)
        raise InputError(f"lens distortion {self} cannot be inverted over this image")


@dataclass(frozen=True)
class BoardPlacement:
    """Pose of a calibration board in the rig frame.

    Attributes
    ----------
    rotation : 3 x 3 tuple
        Columns: the board's x (along its rows of squares), y (down its printed image) and z
        (into the board, away from the printed face) axes in the rig frame. OpenCV's board frame
        has these axes, origin at the top-left chessboard corner.
    centre : (x, y, z)
        Rig position of the centre of the chessboard area.
    """

    rotation: tuple[tuple[float, float, float], ...] = FLAT_BOARD
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def tilted(
        cls,
        tilt_deg: float = 0.0,
        tilt_azimuth_deg: float = 0.0,
        yaw_deg: float = 0.0,
        centre: ArrayLike = (0.0, 0.0, 0.0),
    ) -> BoardPlacement:
        """The board face up at ``centre``, turned about ``+z``, then tilted.

        Turned by ``yaw_deg`` about ``+z`` (CCW from above), then tilted by ``tilt_deg`` so its
        face normal leans toward ``tilt_azimuth_deg``.

        With all angles 0 the printed image reads upright seen from above with its top toward
        ``+y``: board x is rig ``+x``, board y is rig ``-y``.
        """
        flat = np.array(FLAT_BOARD)
        yaw = _rotation(np.array([0.0, 0.0, 1.0]), math.radians(yaw_deg))
        a = math.radians(tilt_azimuth_deg)
        tilt = _rotation(np.array([-math.sin(a), math.cos(a), 0.0]), math.radians(tilt_deg))
        matrix = tilt @ yaw @ flat
        c = np.asarray(centre, dtype=np.float64).reshape(3)
        return cls(
            rotation=tuple((float(r[0]), float(r[1]), float(r[2])) for r in matrix),
            centre=(float(c[0]), float(c[1]), float(c[2])),
        )

    @property
    def matrix(self) -> F64:
        """The rotation as an array; shape (3, 3)."""
        return np.array(self.rotation, dtype=np.float64)


def _rotation(axis: F64, angle: float) -> F64:
    """Rotation matrix about a unit ``axis`` by ``angle`` radians (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


@dataclass(frozen=True)
class DiscLight:
    """A small round light of uniform radiance, seen from the origin under ``angular_size_deg``.

    Attributes
    ----------
    direction : (x, y, z)
        From the origin toward the light (need not be unit length).
    distance : float or None
        None: a distant (directional) light; otherwise the light's centre is at this distance
        from the origin and acts as a point light of radiant intensity ``irradiance x
        distance^2`` on diffuse surfaces.
    angular_size_deg : float
        Full angle the disc subtends at the origin.
    irradiance : float
        Irradiance the light delivers at the origin, on a surface facing it; the disc's radiance
        is this over its solid angle.
    """

    direction: tuple[float, float, float]
    distance: float | None = None
    angular_size_deg: float = 2.0
    irradiance: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 < self.angular_size_deg < 90.0:
            raise InputError(f"light angular size must be in (0, 90) deg: {self.angular_size_deg}")
        if self.distance is not None and not self.distance > 0:
            raise InputError(f"light distance must be positive, got {self.distance}")
        if not (math.isfinite(self.irradiance) and self.irradiance >= 0):
            raise InputError(f"light irradiance must be >= 0, got {self.irradiance}")
        normalize(self.direction)

    @property
    def unit(self) -> F64:
        """Unit direction from the origin toward the light; shape (3,)."""
        return normalize(self.direction)

    @property
    def half_angle(self) -> float:
        """Half the disc's angular size, radians."""
        return math.radians(self.angular_size_deg) / 2.0

    @property
    def radiance(self) -> float:
        """Radiance of the disc's face."""
        solid_angle = 2.0 * math.pi * (1.0 - math.cos(self.half_angle))
        return self.irradiance / solid_angle


@dataclass(frozen=True)
class WhiteTarget:
    """A flat square Lambertian target of ``albedo``, face up, centred at ``centre``.

    ``half_size`` is half its side, in scene units; its normal is ``+z``.
    """

    albedo: float = 0.8
    half_size: float = 1.5
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)


# --- rays ------------------------------------------------------------------------------------


def _pixel_rays(
    camera: PinholeCamera,
    distortion: LensDistortion,
    cols: F64,
    rows: F64,
) -> F64:
    """Unit ray directions (N, 3) in the rig frame through continuous pixel coordinates (N,)."""
    f = camera.focal_px
    x, y = distortion.undistort((cols - 0.5 * camera.width) / f, (rows - 0.5 * camera.height) / f)
    right, up, forward = camera.axes()
    # OpenCV's y points down the image, the camera's up vector points up it.
    d = x[:, None] * right + (-y)[:, None] * up + forward
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _subpixel_pattern(count: int) -> tuple[F64, F64]:
    """``count`` sample offsets (x, y) in the unit pixel, a rank-1 lattice.

    One per column and one per row of a ``count`` x ``count`` grid, so an edge along the pixel
    grid is measured to 1 / count of a pixel rather than to 1 / sqrt(count) as by a square grid.
    """
    k = np.arange(count)
    step = next((a for a in (5, 7, 3) if a < count and math.gcd(a, count) == 1), 1)
    return (k + 0.5) / count, ((k * step) % count + 0.5) / count


def _render(
    camera: PinholeCamera,
    shader: Shader,
    distortion: LensDistortion | None,
    supersample: int,
) -> NDArray[np.float32]:
    """Cast one ray per pixel centre, then re-render non-uniform pixels with s x s rays each."""
    if supersample < 1:
        raise InputError(f"supersample must be >= 1, got {supersample}")
    lens = distortion or LensDistortion()
    height, width = camera.height, camera.width
    origin = camera.position
    image = np.empty((height, width, 3))
    for start in range(0, height, ROWS_PER_CHUNK):
        rows, cols = np.mgrid[start : min(start + ROWS_PER_CHUNK, height), 0:width] + 0.5
        rays = _pixel_rays(camera, lens, cols.ravel(), rows.ravel())
        image[start : start + rows.shape[0]] = shader(origin, rays).reshape(*rows.shape, 3)
    if supersample == 1:
        return image.astype(np.float32)
    # A pixel whose 3 x 3 neighbourhood varies by more than EDGE_CONTRAST may hold an edge;
    # smooth shading (a falloff, the dim surround) is sampled well enough at the centre.
    level = image.max(axis=2)
    padded = np.pad(level, 1, mode="edge")
    high, low = level.copy(), level.copy()
    for dr in range(3):
        for dc in range(3):
            shifted = padded[dr : dr + height, dc : dc + width]
            np.maximum(high, shifted, out=high)
            np.minimum(low, shifted, out=low)
    edge_rows, edge_cols = np.nonzero(high - low > EDGE_CONTRAST * high + 1e-30)
    sub_c, sub_r = _subpixel_pattern(supersample * supersample)
    step = max(1, 400_000 // (supersample * supersample))
    for s in range(0, len(edge_rows), step):
        r = edge_rows[s : s + step]
        c = edge_cols[s : s + step]
        rr = (r[:, None] + sub_r[None, :]).ravel()
        cc = (c[:, None] + sub_c[None, :]).ravel()
        radiance = shader(origin, _pixel_rays(camera, lens, cc, rr))
        image[r, c] = radiance.reshape(len(r), -1, 3).mean(axis=1)
    return image.astype(np.float32)


# --- ChArUco board ---------------------------------------------------------------------------


def _board_texture(board: cv2.aruco.CharucoBoard) -> tuple[NDArray[np.float64], float, float]:
    """The printed board (rows, cols) in [0, 1], texels per unit length, margin in texels."""
    squares_x, squares_y = board.getChessboardSize()
    margin = round(BOARD_MARGIN_SQUARES * TEXELS_PER_SQUARE)
    size = (squares_x * TEXELS_PER_SQUARE + 2 * margin, squares_y * TEXELS_PER_SQUARE + 2 * margin)
    texture = board.generateImage(size, marginSize=margin, borderBits=1)
    return texture.astype(np.float64) / 255.0, TEXELS_PER_SQUARE / board.getSquareLength(), margin


def render_charuco(
    board: cv2.aruco.CharucoBoard,
    camera: PinholeCamera,
    placement: BoardPlacement | None = None,
    *,
    distortion: LensDistortion | None = None,
    white: float = 0.8,
    black: float = 0.04,
    background: float = 0.15,
    supersample: int = 4,
) -> NDArray[np.float32]:
    """A ChArUco board seen by ``camera``: linear radiance (H, W, 3), float32.

    Parameters
    ----------
    board : cv2.aruco.CharucoBoard
        Its square length is in scene units.
    camera : PinholeCamera
    placement : BoardPlacement, optional
        Board pose in the rig frame; default flat at the origin (the object's place).
    distortion : LensDistortion, optional
    white, black, background : float
        Radiance of the board's white and black print and of everything around the board
        (evenly lit, so the printed albedo maps straight to radiance).
    supersample : int
        Rays per pixel side where the pixel may hold an edge.
    """
    place = placement or BoardPlacement()
    texture, texels_per_unit, margin = _board_texture(board)
    squares_x, squares_y = board.getChessboardSize()
    side = board.getSquareLength()
    rotation = place.matrix
    origin = np.asarray(place.centre) - rotation @ np.array(
        [0.5 * squares_x * side, 0.5 * squares_y * side, 0.0]
    )
    normal = rotation[:, 2]
    levels = black + (white - black) * texture

    def shade(eye: F64, rays: F64) -> F64:
        facing = rays @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((origin - eye) @ normal) / facing
        hit = np.isfinite(t) & (t > 0)
        points = eye + np.where(hit, t, 0.0)[:, None] * rays
        local = (points - origin) @ rotation  # board coordinates: rotation is orthonormal
        tex_col = np.floor(local[:, 0] * texels_per_unit + margin).astype(np.int64)
        tex_row = np.floor(local[:, 1] * texels_per_unit + margin).astype(np.int64)
        inside = (
            hit
            & (tex_col >= 0)
            & (tex_col < texture.shape[1])
            & (tex_row >= 0)
            & (tex_row < texture.shape[0])
        )
        value = np.full(len(rays), background)
        value[inside] = levels[tex_row[inside], tex_col[inside]]
        return np.repeat(value[:, None], 3, axis=1)

    return _render(camera, shade, distortion, supersample)


# --- mirror sphere ---------------------------------------------------------------------------


def _environment(directions: F64, level: float) -> F64:
    """A dim, smoothly varying surround (brighter above), radiance (N,)."""
    return level * (0.6 + 0.4 * directions[:, 2])


def _light_hit(points: F64, directions: F64, light: DiscLight) -> NDArray[np.bool_]:
    """Which rays (N,) from ``points`` along ``directions`` reach the disc light."""
    if light.distance is None:
        return directions @ light.unit >= math.cos(light.half_angle)
    centre = light.distance * light.unit
    radius = light.distance * math.tan(light.half_angle)
    # The emitter is a small sphere: a ray reaches it when it passes within its radius, ahead.
    offset = centre - points
    along = np.einsum("nk,nk->n", offset, directions)
    miss2 = np.einsum("nk,nk->n", offset, offset) - along**2
    return (along > 0) & (miss2 <= radius * radius)


def render_mirror_sphere(
    camera: PinholeCamera,
    light: DiscLight,
    *,
    radius: float = 0.5,
    centre: ArrayLike = (0.0, 0.0, 0.0),
    reflectance: float = 0.7,
    environment: float = 0.02,
    distortion: LensDistortion | None = None,
    supersample: int = 4,
) -> NDArray[np.float32]:
    """A chrome ball reflecting one disc light and a dim surround: linear radiance (H, W, 3).

    Parameters
    ----------
    camera : PinholeCamera
    light : DiscLight
        Its reflection is the highlight; a light straight in the camera's view is drawn too.
    radius, centre : float and (3,)
        The sphere in the rig frame, scene units.
    reflectance : float
        Mirror reflectance (chrome is about 0.6 to 0.7).
    environment : float
        Radiance scale of the surround seen directly and in the mirror (the dim background a
        highlight detector must ignore).
    distortion : LensDistortion, optional
    supersample : int
        Rays per pixel side where the pixel may hold an edge.
    """
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    if np.linalg.norm(camera.position - c) <= radius:
        raise InputError(f"camera at {camera.position} is inside the mirror sphere")

    def shade(eye: F64, rays: F64) -> F64:
        offset = eye - c
        b = rays @ offset
        disc = b * b - (offset @ offset - radius * radius)
        hit = (disc >= 0) & (-b - np.sqrt(np.maximum(disc, 0.0)) > 0)
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        points = np.where(hit[:, None], eye + t[:, None] * rays, eye)
        normals = (points - c) / radius
        mirrored = rays - 2.0 * np.einsum("nk,nk->n", rays, normals)[:, None] * normals
        outgoing = np.where(hit[:, None], mirrored, rays)
        value = _environment(outgoing, environment)
        value[_light_hit(points, outgoing, light)] = light.radiance
        value[hit] *= reflectance
        return np.repeat(value[:, None], 3, axis=1)

    return _render(camera, shade, distortion, supersample)


# --- white target ----------------------------------------------------------------------------


def render_white_target(
    camera: PinholeCamera,
    light: DiscLight,
    target: WhiteTarget | None = None,
    *,
    distortion: LensDistortion | None = None,
    background: float = 0.0,
    supersample: int = 1,
) -> NDArray[np.float32]:
    """A flat Lambertian target under one light: linear radiance (H, W, 3), float32.

    Radiance ``albedo / pi x E cos(theta)`` with E the light's irradiance (directional) or
    ``irradiance x distance^2 / r^2`` (point light at ``distance``, r from the light to the
    surface point), theta the angle of incidence. No shadows (nothing stands on the target).
    """
    t = target or WhiteTarget()
    c = np.asarray(t.centre, dtype=np.float64)
    normal = np.array([0.0, 0.0, 1.0])

    def shade(eye: F64, rays: F64) -> F64:
        with np.errstate(divide="ignore", invalid="ignore"):
            along = ((c - eye) @ normal) / (rays @ normal)
        hit = np.isfinite(along) & (along > 0)
        points = eye + np.where(hit, along, 0.0)[:, None] * rays
        local = points - c
        hit &= (np.abs(local[:, 0]) <= t.half_size) & (np.abs(local[:, 1]) <= t.half_size)
        if light.distance is None:
            cosine = np.full(len(rays), float(light.unit @ normal))
            irradiance = np.full(len(rays), light.irradiance)
        else:
            towards = light.distance * light.unit - points
            r2 = np.einsum("nk,nk->n", towards, towards)
            cosine = (towards @ normal) / np.sqrt(r2)
            irradiance = light.irradiance * light.distance**2 / r2
        value = np.where(hit, t.albedo / math.pi * irradiance * np.maximum(cosine, 0.0), background)
        return np.repeat(value[:, None], 3, axis=1)

    return _render(camera, shade, distortion, supersample)


# --- sensor ----------------------------------------------------------------------------------


def record(
    radiance: NDArray[np.floating],
    sensor: Sensor | None = None,
    *,
    output: Literal["linear16", "srgb8"] = "linear16",
    seed: int = 0,
) -> NDArray[np.uint16] | NDArray[np.uint8]:
    """Pass a rendered target through the sensor model, as the simulated camera does.

    Parameters
    ----------
    radiance : ndarray, shape (H, W, 3), linear radiance
    sensor : Sensor, optional (default :class:`sim.sensor.Sensor`)
    output : {"linear16", "srgb8"}
        16-bit linear (0 black, 65535 saturation) or 8-bit sRGB.
    seed : int, sensor-noise seed

    Returns
    -------
    ndarray, shape (H, W, 3), uint16 or uint8
    """
    s = sensor or Sensor()
    dn = expose(radiance, s, seed)
    if output == "linear16":
        return to_linear16(dn, s)
    if output == "srgb8":
        return to_srgb8(dn, s)
    raise InputError(f"unknown output {output!r}; use 'linear16' or 'srgb8'")
