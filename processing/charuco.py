"""Camera intrinsics and camera poses from ChArUco boards (OpenCV's ``CharucoDetector``).

- :func:`calibrate_intrinsics`: several views of a board in different poses, one camera;
  ``cv2.calibrateCamera`` on the detected ChArUco corners.
- :func:`board_extrinsics`: one view of a board lying at the object's place, at one camera pose
  of the rig; ``cv2.solvePnP`` gives the camera in the board's frame, and the board's known
  placement turns it into the rig frame (:class:`processing.calibration.CameraPose`), compared
  with the pose the rig's kinematics claim.

The board's frame is OpenCV's: origin at the top-left chessboard corner of the printed image,
x along its rows, y down the image, z into the board. :class:`ChArUcoTarget` says where that frame
sits in the rig frame (default: face up, centred at the origin, image upright seen from above
with its top toward ``+y``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from core.calibrated_camera import CameraPose, Intrinsics
from core.camera_model import PinholeCamera
from core.errors import InputError
from processing.calibration import ImageInput, gray8, linear_luminance, load_image

__all__ = [
    "FLAT_BOARD",
    "BoardView",
    "ChArUcoTarget",
    "board_extrinsics",
    "calibrate_intrinsics",
    "detect_board",
]

F64 = NDArray[np.float64]
#: Board axes (columns, in the rig frame) of a board lying face up, image upright from above.
FLAT_BOARD = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
#: Fewest corners a view must give: calibrateCamera's homography initialisation needs 4 and a
#: pose fit from fewer than about 6 corners on a plane is fragile.
MIN_CORNERS = 6


@dataclass(frozen=True)
class ChArUcoTarget:
    """A printed ChArUco board and where it lies in the rig frame.

    Attributes
    ----------
    squares_x, squares_y : int, chessboard squares along the board's x and y
    square_length, marker_length : float, scene units (the board's lengths set the scale)
    dictionary : str, an OpenCV predefined dictionary name (``cv2.aruco.DICT_*``)
    rotation : 3 x 3, columns: the board's x, y and z axes in the rig frame
    centre : (x, y, z), rig position of the centre of the chessboard area
    """

    squares_x: int = 7
    squares_y: int = 5
    square_length: float = 0.25
    marker_length: float = 0.18
    dictionary: str = "DICT_5X5_100"
    rotation: tuple[tuple[float, float, float], ...] = FLAT_BOARD
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _board: list[cv2.aruco.CharucoBoard] = field(
        default_factory=list, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if self.squares_x < 2 or self.squares_y < 2:
            raise InputError(f"a ChArUco board needs 2 x 2 squares or more: {self}")
        if not 0 < self.marker_length < self.square_length:
            raise InputError(
                f"marker length {self.marker_length} must be positive and below the square "
                f"length {self.square_length}"
            )
        if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
            raise InputError(f"unknown ArUco dictionary {self.dictionary!r}")
        r = self.placement_rotation
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InputError(f"board rotation must be a proper rotation matrix: {self.rotation}")

    def board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board (created once)."""
        if not self._board:
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
            self._board.append(
                cv2.aruco.CharucoBoard(
                    (self.squares_x, self.squares_y),
                    self.square_length,
                    self.marker_length,
                    dictionary,
                )
            )
        return self._board[0]

    @property
    def placement_rotation(self) -> F64:
        """Board-to-rig rotation (3, 3): columns are the board's axes in the rig frame."""
        return np.array(self.rotation, dtype=np.float64)

    @property
    def origin(self) -> F64:
        """Rig position of the board frame's origin (its top-left chessboard corner); (3,)."""
        half = 0.5 * self.square_length * np.array([self.squares_x, self.squares_y, 0.0])
        return np.asarray(self.centre, dtype=np.float64) - self.placement_rotation @ half


@dataclass(frozen=True)
class BoardView:
    """ChArUco corners found in one image.

    Attributes
    ----------
    ids : ndarray (N,), int32, corner ids
    object_points : ndarray (N, 3), float32, board-frame positions, scene units
    image_points : ndarray (N, 2), float32, OpenCV pixel coordinates (pixel centres at integers)
    """

    ids: NDArray[np.int32]
    object_points: NDArray[np.float32]
    image_points: NDArray[np.float32]


def detect_board(
    image: ImageInput, target: ChArUcoTarget, *, name: str = "image", min_corners: int = MIN_CORNERS
) -> BoardView:
    """Find the ChArUco corners of ``target`` in one image.

    Parameters
    ----------
    image : array (H, W) or (H, W, 3), uint8 (sRGB), uint16 or float (linear), or a path
    target : ChArUcoTarget
    name : str, how errors name the image
    min_corners : int, fewest corners accepted

    Raises
    ------
    InputError
        Fewer than ``min_corners`` corners, or all of them on one line; the message names the
        image.
    """
    array = load_image(image, name)
    pixels = gray8(array, name)
    board = target.board()
    detector = cv2.aruco.CharucoDetector(board)
    corners, ids, _, marker_ids = detector.detectBoard(pixels)
    found = 0 if ids is None else len(ids)
    if found < min_corners:
        markers = 0 if marker_ids is None else len(marker_ids)
        raise InputError(
            f"{name}: found {found} ChArUco corners ({markers} markers), need at least "
            f"{min_corners}; is the {target.squares_x}x{target.squares_y} {target.dictionary} "
            f"board in view, lit and in focus?"
        )
    if board.checkCharucoCornersCollinear(ids):
        raise InputError(f"{name}: the {found} ChArUco corners found lie on one line")
    gap = 0.5 * (target.square_length - target.marker_length) / target.square_length
    # Refined on linear light: the sRGB curve skews the blurred edges' gradients.
    linear = linear_luminance(array, name).astype(np.float32)
    corners = _refine_corners(linear, np.asarray(corners, dtype=np.float32), gap)
    # A ChArUco board takes the (N, 1, 2) corner array itself; the stub only knows the marker
    # form (a sequence of quads).
    object_points, image_points = board.matchImagePoints(corners, ids)  # type: ignore[call-overload]
    return BoardView(
        ids=np.asarray(ids, dtype=np.int32).reshape(-1),
        object_points=np.asarray(object_points, dtype=np.float32).reshape(-1, 3),
        image_points=np.asarray(image_points, dtype=np.float32).reshape(-1, 2),
    )


def _refine_corners(
    pixels: NDArray[np.float32], corners: NDArray[np.float32], gap: float
) -> NDArray[np.float32]:
    """Saddle-point refinement of ChArUco corners with a window sized to the squares.

    The detector's own refinement leaves errors of about 0.3 pixel on sharp synthetic views;
    ``cornerSubPix`` over a window that stays inside the white border around the markers
    (``gap``, that border as a fraction of a square) brings them to a few hundredths.
    """
    points = corners.reshape(-1, 2).astype(np.float64)
    gaps = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    np.fill_diagonal(gaps, np.inf)
    square_px = float(np.median(gaps.min(axis=1)))
    half = int(np.clip(0.7 * gap * square_px, 2, 12))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-4)
    refined = cv2.cornerSubPix(
        pixels, corners.reshape(-1, 1, 2).copy(), (half, half), (-1, -1), criteria
    )
    return np.asarray(refined, dtype=np.float32)


def _names(count: int, names: Sequence[str] | None, what: str) -> list[str]:
    if names is None:
        return [f"{what} {i}" for i in range(count)]
    if len(names) != count:
        raise InputError(f"got {len(names)} names for {count} images")
    return [str(n) for n in names]


def calibrate_intrinsics(
    images: Sequence[ImageInput],
    target: ChArUcoTarget,
    *,
    names: Sequence[str] | None = None,
    fix_k3: bool = True,
    zero_tangential: bool = False,
    min_corners: int = MIN_CORNERS,
) -> Intrinsics:
    """Camera intrinsics from several views of a ChArUco board.

    Parameters
    ----------
    images : sequence of arrays (H, W) or (H, W, 3) or paths, one camera, >= 3 board poses
        (tilted differently: the focal length comes from perspective foreshortening)
    target : ChArUcoTarget (its placement is not used)
    names : sequence of str, optional, how errors name the images (file names)
    fix_k3, zero_tangential : bool
        Hold ``k3`` (and ``p1, p2``) at 0: a few views cannot separate high-order terms.
    min_corners : int, fewest corners an image must give

    Returns
    -------
    Intrinsics
        Focal lengths and principal point in pixels (pixel centres at + 0.5, see
        :mod:`processing.calibration`), distortion, RMS reprojection error over all corners.
    """
    labels = _names(len(images), names, "intrinsics image")
    if len(images) < 3:
        raise InputError(f"intrinsics need at least 3 board views, got {len(images)}")
    views: list[BoardView] = []
    size: tuple[int, int] | None = None
    for image, label in zip(images, labels, strict=True):
        array = load_image(image, label)
        if size is None:
            size = (array.shape[1], array.shape[0])
        elif (array.shape[1], array.shape[0]) != size:
            raise InputError(f"{label}: size {array.shape[1]}x{array.shape[0]} differs from {size}")
        views.append(detect_board(array, target, name=label, min_corners=min_corners))
    assert size is not None
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    if zero_tangential:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, matrix, distortion, _, _ = cv2.calibrateCamera(
        [v.object_points for v in views],
        [v.image_points for v in views],
        size,
        None,
        None,
        flags=flags,
        criteria=criteria,
    )
    k = np.asarray(matrix, dtype=np.float64)
    d = np.zeros(5)
    d[: min(5, np.size(distortion))] = np.asarray(distortion, dtype=np.float64).ravel()[:5]
    return Intrinsics(
        width=size[0],
        height=size[1],
        fx=float(k[0, 0]),
        fy=float(k[1, 1]),
        cx=float(k[0, 2]) + 0.5,  # OpenCV centres pixels at integers
        cy=float(k[1, 2]) + 0.5,
        distortion=(float(d[0]), float(d[1]), float(d[2]), float(d[3]), float(d[4])),
        rms_px=float(rms),
        views=len(views),
    )


def board_extrinsics(
    image: ImageInput,
    intrinsics: Intrinsics,
    target: ChArUcoTarget,
    *,
    nominal: PinholeCamera | None = None,
    name: str = "extrinsics image",
    min_corners: int = MIN_CORNERS,
) -> CameraPose:
    """A camera's pose in the rig frame from one view of a board at a known place.

    Parameters
    ----------
    image : array (H, W) or (H, W, 3) or path, taken at one camera pose of the rig
    intrinsics : Intrinsics, of the same camera (same image size)
    target : ChArUcoTarget, with its placement in the rig frame (usually flat at the origin)
    nominal : PinholeCamera, optional
        The camera the rig's kinematics claim for this pose; the result then carries its
        :class:`~processing.calibration.PoseDisagreement` with it.
    name : str, how errors name the image
    min_corners : int, fewest corners accepted

    Returns
    -------
    CameraPose
        Camera centre and axes in the rig frame, RMS reprojection error in pixels, corners used.
    """
    array = load_image(image, name)
    if (array.shape[1], array.shape[0]) != (intrinsics.width, intrinsics.height):
        raise InputError(
            f"{name}: size {array.shape[1]}x{array.shape[0]} differs from the intrinsics' "
            f"{intrinsics.width}x{intrinsics.height}"
        )
    view = detect_board(array, target, name=name, min_corners=min_corners)
    matrix, distortion = intrinsics.camera_matrix(), intrinsics.distortion_array()
    # IPPE is the closed form for planar targets; Levenberg-Marquardt then polishes it.
    ok, rvec, tvec = cv2.solvePnP(
        view.object_points, view.image_points, matrix, distortion, flags=cv2.SOLVEPNP_IPPE
    )
    if not ok:
        raise InputError(f"{name}: solvePnP found no camera pose for the board")
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    rvec, tvec = cv2.solvePnPRefineLM(
        view.object_points, view.image_points, matrix, distortion, rvec, tvec, criteria
    )
    projected, _ = cv2.projectPoints(view.object_points, rvec, tvec, matrix, distortion)
    residual = projected.reshape(-1, 2) - view.image_points
    rms = math.sqrt(float(np.mean(np.sum(residual.astype(np.float64) ** 2, axis=1))))
    board_to_camera, _ = cv2.Rodrigues(rvec)
    # camera <- board <- rig: x_board = B^T (x_rig - o), with B the board-to-rig rotation.
    b = target.placement_rotation
    rotation = np.asarray(board_to_camera, dtype=np.float64) @ b.T
    translation = np.asarray(tvec, dtype=np.float64).reshape(3) - rotation @ target.origin
    pose = CameraPose.from_opencv(rotation, translation)
    disagreement = pose.compare(nominal) if nominal is not None else None
    return CameraPose(
        position=pose.position,
        axes=pose.axes,
        rms_px=rms,
        corners=len(view.ids),
        disagreement=disagreement,
    )
