"""Calibration targets: checkerboards, Kalibr's AprilGrid and OpenCV's ChArUco.

A target is a plane of identified corners. :class:`Checkerboard`, :class:`AprilGrid` and
:class:`Charuco` give every corner's id ``j`` (``0 .. n_corners - 1``) and its position
``points()[j]`` in the target's frame (metres, ``z = 0``); :func:`detect_target` finds the
corners of one grey image as ``(ids, pixels)``. An AprilGrid or ChArUco view that shows
only part of the target still yields identified corners: :func:`pose_ready` says whether
they determine a pose.

Frames and numbering:

- **checkerboard**: acscal's board frame (origin at the first inner corner, x along a row
  of ``cols`` corners, y along the rows, z into the board); corner ``j`` at
  ``(j % cols, j // cols, 0) * square`` (OpenCV's order).
- **aprilgrid** (Kalibr's ``GridCalibrationTargetAprilgrid``): ``tag_cols x tag_rows``
  tag36h11 tags of side ``tag_size`` (the black border's outer edge), ``spacing *
  tag_size`` apart; tag 0 at the bottom left as printed, ids increasing along a row then
  upwards. Each tag is drawn as Kalibr's ``createTargetPDF.py`` draws it
  (:func:`aprilgrid_tag_cells`): the official AprilTag image of its code, with a black
  border :data:`KALIBR_BORDER_BITS` = 2 bits wide, so ``tag_size`` spans 10 bits. Origin
  at tag 0's bottom-left corner, x right, y up (z out of the board). The corners form a
  ``2 tag_rows x 2 tag_cols`` grid numbered row by row from the bottom, as Kalibr numbers
  its grid points: point ``j`` at grid row ``r = j // (2 tag_cols)``, column ``c = j % (2
  tag_cols)``, position ``((c // 2) (1 + spacing) s + (c % 2) s, (r // 2)
  (1 + spacing) s + (r % 2) s, 0)``. Tag ``t``'s corners (bottom-left, bottom-right,
  top-right, top-left) are points ``b, b + 1, b + 2 tag_cols + 1, b + 2 tag_cols`` with
  ``b = 4 tag_cols (t // tag_cols) + 2 (t % tag_cols)``. Kalibr's black squares between
  the tags' corners make every tag corner an X-junction.
- **charuco** (OpenCV's ``CharucoBoard``, the current layout): ``squares_x x squares_y``
  squares of ``square_length``, markers of ``marker_length`` in the white squares, the
  first marker in the top-left square. Its ``(squares_x - 1) (squares_y - 1)`` inner
  chessboard corners are numbered row by row from the top left, at ``((j % (squares_x -
  1) + 1) L, (j // (squares_x - 1) + 1) L, 0)`` (origin at the board's top-left corner, x
  right, y down, z into the board), as ``CharucoBoard.getChessboardCorners`` gives them.

Detection (:func:`detect_target`): ``cv2.aruco.ArucoDetector`` (AprilGrid: Kalibr's
two-bit tag border, corners from the lines of the tags' edges) or
``cv2.aruco.CharucoDetector`` (ChArUco) for the identified corners, then each corner is
refined to sub-pixel as the X-junction it is (``cv2.cornerSubPix`` and the saddle fit of
:func:`acs_cli.core.checkerboard.refine_saddle`) with windows sized from the local scale
of the tags (a fraction of one AprilGrid tag bit, or of a ChArUco square's white margin),
so that neither reaches the marker's data bits. OpenCV 4's
``DICT_APRILTAG_36h11`` markers are the official tag images turned half a turn (OpenCV 5
draws them upright): the turn is read from the installed OpenCV once
(:data:`ARUCO_APRILTAG_TURNS`), and ArUco's corners are mapped to the printed ones with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.core.checkerboard import detect_checkerboard, refine_saddle
from acs_cli.core.intrinsics import board_points

__all__ = [
    "ARUCO_APRILTAG_TURNS",
    "ARUCO_DICTIONARIES",
    "KALIBR_BORDER_BITS",
    "KALIBR_CORNERS_FROM_ARUCO",
    "MIN_POSE_CORNERS",
    "TARGETS_DETECTOR_VERSION",
    "TARGET_KINDS",
    "AprilGrid",
    "Charuco",
    "Checkerboard",
    "MarkerTarget",
    "Target",
    "TargetDetection",
    "aprilgrid_tag_cells",
    "detect_target",
    "find_other_family",
    "pose_ready",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Recorded in detection caches of AprilGrid and ChArUco targets: bump when the output
#: of :func:`detect_target` can change.
TARGETS_DETECTOR_VERSION = "acscal-targets-2"
#: The kinds of target, as ``target_type`` names them.
TARGET_KINDS = ("checkerboard", "aprilgrid", "charuco")
#: Fewest identified corners of one view used for a pose or a calibration.
MIN_POSE_CORNERS = 8
#: Smallest ratio of the second to the first singular value of a view's centred target
#: points: below it the corners are (nearly) collinear and determine no pose.
MIN_SPREAD = 0.05

#: The ArUco dictionaries a target may name, by OpenCV's name.
ARUCO_DICTIONARIES: dict[str, int] = {
    name: int(getattr(cv2.aruco, name))
    for name in (
        *(f"DICT_{b}X{b}_{n}" for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)),
        "DICT_ARUCO_ORIGINAL",
        "DICT_APRILTAG_16h5",
        "DICT_APRILTAG_25h9",
        "DICT_APRILTAG_36h10",
        "DICT_APRILTAG_36h11",
        "DICT_ARUCO_MIP_36h12",
    )
}
#: One dictionary of each family (the largest), for :func:`find_other_family`.
_FAMILIES: dict[str, str] = {
    "DICT_4X4": "DICT_4X4_1000",
    "DICT_5X5": "DICT_5X5_1000",
    "DICT_6X6": "DICT_6X6_1000",
    "DICT_7X7": "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL": "DICT_ARUCO_ORIGINAL",
    "DICT_APRILTAG_16h5": "DICT_APRILTAG_16h5",
    "DICT_APRILTAG_25h9": "DICT_APRILTAG_25h9",
    "DICT_APRILTAG_36h10": "DICT_APRILTAG_36h10",
    "DICT_APRILTAG_36h11": "DICT_APRILTAG_36h11",
    "DICT_ARUCO_MIP_36h12": "DICT_ARUCO_MIP_36h12",
}
#: Markers of another family an image must show before :func:`find_other_family` names it.
MIN_FAMILY_MARKERS = 3

#: ``cornerSubPix`` half-window, as a fraction of one tag bit (AprilGrid) or of a ChArUco
#: square's white margin around its marker.
WINDOW_FRACTION = 0.7
#: Half-window of a first, wider ``cornerSubPix`` pass (the markers' corners can be a few
#: pixels off), as the same fraction.
WIDE_FRACTION = 1.2
#: Saddle-fit radius, as the same fraction.
SADDLE_FRACTION = 0.6
#: Refined corners that moved farther than this fraction of their window are dropped.
MAX_SHIFT_FRACTION = 0.75
#: Rounds of predicting missed AprilGrid tags from the found ones.
GROW_ROUNDS = 3
#: Found tags whose corners predict a missed one.
NEAR_TAGS = 4
#: Smallest tag side (pixels) a predicted tag is looked for at.
MIN_TAG_PX = 16.0
#: Cells of a predicted tag (of 100, border included) that may read wrong.
MAX_WRONG_CELLS = 2
#: Smallest grey-level contrast between a predicted tag's dark and light cells.
MIN_CONTRAST = 25.0
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)

#: Width of an AprilGrid tag's black border, in bits: Kalibr draws 2 (``createTargetPDF.py``'s
#: ``borderBits``) and its detector expects 2 (``blackTagBorder``), so ``tagSize`` spans
#: ``6 + 2 * 2`` bits. OpenCV's ArUco default (``markerBorderBits``) is 1.
KALIBR_BORDER_BITS = 2
#: Data bits along a tag36h11 tag's side.
_TAG36H11_BITS = 6
#: tag36h11 tag 0 as the AprilTag library (and Kalibr's ``createTargetPDF.py``) codes it:
#: bit 35 is the top-left data cell of the official image, then row by row, 1 = white.
_TAG36H11_CODE_0 = 0xD5D628584


def _aruco_apriltag_turns() -> int:
    """Quarter turns (``np.rot90``) from OpenCV's ``DICT_APRILTAG_36h11`` marker images to
    the official AprilTag images, read from ``generateImageMarker`` for tag 0.

    Raises
    ------
    RuntimeError
        The installed OpenCV's tag 0 is no turn of the official one.
    """
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    b = _TAG36H11_BITS
    drawn = cv2.aruco.generateImageMarker(d, 0, b + 2, borderBits=1)[1:-1, 1:-1] > 0
    shifts = b * b - 1 - np.arange(b * b)
    official = ((_TAG36H11_CODE_0 >> shifts) & 1).astype(bool).reshape(b, b)
    for turns in range(4):
        if np.array_equal(np.rot90(drawn, turns), official):
            return turns
    raise RuntimeError(
        f"OpenCV {cv2.__version__}: DICT_APRILTAG_36h11 tag 0 is not the AprilTag library's"
    )


#: Quarter turns (``np.rot90``, counter-clockwise) that bring the installed OpenCV's
#: ``DICT_APRILTAG_36h11`` marker images to the official AprilTag images, which Kalibr
#: prints: 2 in OpenCV 4, 0 once OpenCV draws them upright (OpenCV 5).
ARUCO_APRILTAG_TURNS = _aruco_apriltag_turns()
#: ArUco's corners (top-left, top-right, bottom-right, bottom-left of OpenCV's marker
#: image) that are a printed AprilGrid tag's bottom-left, bottom-right, top-right and
#: top-left corners (Kalibr's order): the printed corner ``p`` (clockwise from the top
#: left) is ArUco's ``(p + ARUCO_APRILTAG_TURNS) % 4``.
KALIBR_CORNERS_FROM_ARUCO = (np.array([3, 2, 1, 0]) + ARUCO_APRILTAG_TURNS) % 4


def aprilgrid_tag_cells(tag_ids: NDArray[np.integer]) -> NDArray[np.bool_]:
    """AprilGrid tags as Kalibr prints them, one boolean a cell (True = white).

    Parameters
    ----------
    tag_ids : array of int, shape (k,)
        tag36h11 ids.

    Returns
    -------
    ndarray of bool, shape (k, 10, 10)
        Row 0 is the printed top, column 0 the left: the official AprilTag image of each
        code inside a black border :data:`KALIBR_BORDER_BITS` cells wide.
    """
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    b, m = _TAG36H11_BITS, KALIBR_BORDER_BITS
    t = np.asarray(tag_ids, dtype=np.int64).reshape(-1)
    out = np.zeros((t.size, b + 2 * m, b + 2 * m), dtype=bool)
    for i, tag in enumerate(t):  # one small lookup a tag
        code = d.getBitsFromByteList(d.bytesList[int(tag) : int(tag) + 1], b) > 0
        out[i, m:-m, m:-m] = np.rot90(code, ARUCO_APRILTAG_TURNS)
    return out


def _family_of(dictionary: str) -> str:
    """``"DICT_5X5_100"`` -> ``"DICT_5X5"``; AprilTag and other names are their own family."""
    for family in _FAMILIES:
        if dictionary == family or dictionary.startswith(family + "_"):
            return family
    return dictionary


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard of ``cols x rows`` inner corners and squares of ``square`` metres."""

    cols: int
    rows: int
    square: float

    kind = "checkerboard"

    def __post_init__(self) -> None:
        if self.cols < 2 or self.rows < 2:
            raise ValueError(f"a checkerboard needs at least 2x2 inner corners: {self}")
        if not (np.isfinite(self.square) and self.square > 0):
            raise ValueError(f"the square must be a positive length: {self}")

    @property
    def n_corners(self) -> int:
        """Corners of the target (``cols * rows``)."""
        return self.cols * self.rows

    def points(self) -> FloatArray:
        """Every corner in the board frame, shape ``(cols * rows, 3)``, metres."""
        return board_points(self.cols, self.rows, self.square)

    def short(self) -> str:
        """The ``--target`` short form, ``checkerboard:COLSxROWS:SQUARE``."""
        return f"checkerboard:{self.cols}x{self.rows}:{self.square:g}"


@dataclass(frozen=True)
class AprilGrid:
    """Kalibr's AprilGrid: ``tag_cols x tag_rows`` tag36h11 tags.

    Attributes
    ----------
    tag_cols, tag_rows : int
        Tags along x and along y (Kalibr's ``tagCols``, ``tagRows``).
    tag_size : float
        Side of a tag, metres (``tagSize``): the outer edge of its black border, which is
        :data:`KALIBR_BORDER_BITS` = 2 of the tag's 10 bits wide, as Kalibr prints it.
    spacing : float
        Gap between tags as a fraction of ``tag_size`` (``tagSpacing``).
    """

    tag_cols: int
    tag_rows: int
    tag_size: float
    spacing: float

    kind = "aprilgrid"
    dictionary = "DICT_APRILTAG_36h11"

    def __post_init__(self) -> None:
        if self.tag_cols < 1 or self.tag_rows < 1:
            raise ValueError(f"an AprilGrid needs at least one tag: {self}")
        if self.tag_cols * self.tag_rows > 587:
            raise ValueError(f"tag36h11 has 587 tags, the grid needs more: {self}")
        if not (np.isfinite(self.tag_size) and self.tag_size > 0):
            raise ValueError(f"the tag size must be a positive length: {self}")
        if not (np.isfinite(self.spacing) and self.spacing > 0):
            raise ValueError(f"the tag spacing must be a positive ratio: {self}")

    @property
    def n_corners(self) -> int:
        """Corners of the target (4 per tag)."""
        return 4 * self.tag_cols * self.tag_rows

    def points(self) -> FloatArray:
        """Every corner in the target frame (Kalibr's), shape ``(4 tags, 3)``, metres."""
        j = np.arange(self.n_corners)
        r, c = np.divmod(j, 2 * self.tag_cols)
        pitch = (1.0 + self.spacing) * self.tag_size
        x = (c // 2) * pitch + (c % 2) * self.tag_size
        y = (r // 2) * pitch + (r % 2) * self.tag_size
        return np.stack([x, y, np.zeros_like(x, dtype=float)], axis=1).astype(float)

    def tag_corner_ids(self, tag_ids: NDArray[np.integer]) -> IntArray:
        """Corner ids of tags, shape ``(k, 4)``: bottom-left, bottom-right, top-right,
        top-left (as printed), Kalibr's numbering."""
        t = np.asarray(tag_ids, dtype=np.int64).reshape(-1)
        w = 2 * self.tag_cols
        base = 2 * w * (t // self.tag_cols) + 2 * (t % self.tag_cols)
        return np.stack([base, base + 1, base + w + 1, base + w], axis=1)

    def short(self) -> str:
        """The ``--target`` short form, ``aprilgrid:COLSxROWS:TAGSIZE:SPACING``."""
        return f"aprilgrid:{self.tag_cols}x{self.tag_rows}:{self.tag_size:g}:{self.spacing:g}"


@dataclass(frozen=True)
class Charuco:
    """OpenCV's ChArUco board.

    Attributes
    ----------
    squares_x, squares_y : int
        Squares along x and y (``squaresX``, ``squaresY``).
    square_length : float
        Side of a square, metres (``squareLength``).
    marker_length : float
        Side of a marker, metres (``markerLength``), less than ``square_length``.
    dictionary : str
        OpenCV's name of the markers' dictionary, e.g. ``"DICT_5X5_100"``.
    """

    squares_x: int
    squares_y: int
    square_length: float
    marker_length: float
    dictionary: str

    kind = "charuco"

    def __post_init__(self) -> None:
        if self.squares_x < 3 or self.squares_y < 3:
            raise ValueError(f"a ChArUco board needs at least 3x3 squares: {self}")
        if not (np.isfinite(self.square_length) and self.square_length > 0):
            raise ValueError(f"the square length must be a positive length: {self}")
        if not (np.isfinite(self.marker_length) and 0 < self.marker_length < self.square_length):
            raise ValueError(f"the marker length must be in (0, square length): {self}")
        if self.dictionary not in ARUCO_DICTIONARIES:
            raise ValueError(f"unknown ArUco dictionary {self.dictionary!r}")
        n_markers = (self.squares_x * self.squares_y) // 2
        if n_markers > _dictionary_size(self.dictionary):
            raise ValueError(
                f"{self.dictionary} has {_dictionary_size(self.dictionary)} markers, the board "
                f"needs {n_markers}"
            )

    @property
    def n_corners(self) -> int:
        """Inner chessboard corners, ``(squares_x - 1) (squares_y - 1)``."""
        return (self.squares_x - 1) * (self.squares_y - 1)

    def board(self) -> cv2.aruco.CharucoBoard:
        """OpenCV's ``CharucoBoard`` of this target."""
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y),
            self.square_length,
            self.marker_length,
            cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARIES[self.dictionary]),
        )

    def points(self) -> FloatArray:
        """Every inner corner in the board frame, shape ``(n_corners, 3)``, metres."""
        return np.asarray(self.board().getChessboardCorners(), dtype=float).reshape(-1, 3)

    def short(self) -> str:
        """The ``--target`` short form, ``charuco:SXxSY:SQUARE:MARKER:DICTIONARY``."""
        return (
            f"charuco:{self.squares_x}x{self.squares_y}:{self.square_length:g}:"
            f"{self.marker_length:g}:{self.dictionary}"
        )


Target = Checkerboard | AprilGrid | Charuco
#: The targets of identified corners (partial views count).
MarkerTarget = AprilGrid | Charuco


def _dictionary_size(name: str) -> int:
    d = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARIES[name])
    return int(d.bytesList.shape[0])


@dataclass(frozen=True)
class TargetDetection:
    """The identified corners of one image.

    Attributes
    ----------
    ids : ndarray of int64, shape (k,)
        Corner ids (rows of the target's ``points()``), increasing, unique.
    pixels : ndarray, shape (k, 2)
        Their positions, pixels (OpenCV: the centre of the top-left pixel at ``(0, 0)``).
    """

    ids: IntArray
    pixels: FloatArray

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def dense(self, n_corners: int) -> FloatArray:
        """The corners as an ``(n_corners, 2)`` array, row ``j`` = corner ``j``, NaN where
        unseen."""
        out = np.full((int(n_corners), 2), np.nan)
        out[self.ids] = self.pixels
        return out


def _empty() -> TargetDetection:
    return TargetDetection(np.zeros(0, np.int64), np.zeros((0, 2)))


def _gray(image: NDArray[np.generic]) -> NDArray[np.uint8]:
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim != 2:
        raise ValueError(f"expected a grey image (h, w), got shape {img.shape}")
    if img.dtype != np.uint8:  # e.g. 16-bit: stretched to 8 bits
        f = img.astype(np.float64)
        lo, hi = float(f.min()), float(f.max())
        img = np.rint(255.0 * (f - lo) / (hi - lo if hi > lo else 1.0)).astype(np.uint8)
    return np.ascontiguousarray(img)


def _detector(
    dictionary: str, border_bits: int = 1, refinement: int = cv2.aruco.CORNER_REFINE_NONE
) -> cv2.aruco.ArucoDetector:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = refinement
    params.markerBorderBits = int(border_bits)
    return cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARIES[dictionary]), params
    )


def _refine_junctions(gray: NDArray[np.uint8], pts: FloatArray, scale: FloatArray) -> FloatArray:
    """Refine X-junctions ``pts`` (k, 2) whose feature scale (px, (k,)) sizes the windows.

    ``cornerSubPix`` with a half-window of :data:`WINDOW_FRACTION` x scale, then the saddle
    fit of :func:`refine_saddle` with radius :data:`SADDLE_FRACTION` x scale; corners are
    grouped by window size (one OpenCV call a group). Corners that move farther than
    :data:`MAX_SHIFT_FRACTION` of the wide window, or whose fine window leaves the image,
    become NaN.
    """
    out = np.asarray(pts, dtype=float).copy()
    wide = np.clip(np.round(WIDE_FRACTION * scale), 2, 20).astype(int)
    half = np.clip(np.round(WINDOW_FRACTION * scale), 2, 15).astype(int)
    radius = np.clip(np.round(SADDLE_FRACTION * scale), 2, 12).astype(int)
    h, w = gray.shape
    for windows in (wide, half):
        for hw in np.unique(windows):
            sel = np.flatnonzero(windows == hw)
            out[sel] = cv2.cornerSubPix(
                gray,
                out[sel].astype(np.float32).reshape(-1, 1, 2),
                (int(hw), int(hw)),
                (-1, -1),
                _SUBPIX_CRITERIA,
            ).reshape(-1, 2)
    for r in np.unique(radius):
        sel = np.flatnonzero(radius == r)
        out[sel] = refine_saddle(gray, out[sel], int(r), blur_sigma=1.0)
    shift = np.linalg.norm(out - pts, axis=1)
    edge = half + 1.0  # the fine window must lie in the image: clipped ones are biased
    bad = (
        ~np.all(np.isfinite(out), axis=1)
        | (shift > MAX_SHIFT_FRACTION * wide)
        | (out[:, 0] < edge)
        | (out[:, 1] < edge)
        | (out[:, 0] > w - 1 - edge)
        | (out[:, 1] > h - 1 - edge)
    )
    out[bad] = np.nan
    return out


def _marker_side_px(quads: FloatArray) -> FloatArray:
    """Mean side length (px) of each detected marker quad, ``quads`` (k, 4, 2)."""
    d = np.linalg.norm(quads - np.roll(quads, -1, axis=1), axis=2)
    return np.asarray(d.mean(axis=1), dtype=float)


def _collect(ids: IntArray, pixels: FloatArray) -> TargetDetection:
    """Drop NaN corners and duplicates (a corner seen twice keeps the mean if they agree)."""
    ok = np.all(np.isfinite(pixels), axis=1)
    ids, pixels = ids[ok], pixels[ok]
    if ids.size == 0:
        return _empty()
    order = np.argsort(ids, kind="stable")
    ids, pixels = ids[order], pixels[order]
    uniq, start, count = np.unique(ids, return_index=True, return_counts=True)
    sums = np.add.reduceat(pixels, start, axis=0)
    mean = sums / count[:, None]
    # a corner of two tags that disagree by more than a pixel is dropped
    spread = np.zeros(uniq.size)
    dev = np.linalg.norm(pixels - np.repeat(mean, count, axis=0), axis=1)
    np.maximum.at(spread, np.repeat(np.arange(uniq.size), count), dev)
    keep = spread <= 1.0
    return TargetDetection(uniq[keep].astype(np.int64), mean[keep])


def _verify_tags(
    gray: NDArray[np.uint8], quads: FloatArray, bits: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """Whether the image shows the expected cells inside predicted tag quads.

    ``quads`` (k, 4, 2) are the tags' corners in Kalibr's order (bottom-left, bottom-right,
    top-right, top-left as printed); each cell centre is sampled through the quad's
    homography, thresholded halfway between the darkest and brightest samples of the tag,
    and compared with ``bits`` (k, b, b), the printed cells (:func:`aprilgrid_tag_cells`).
    A tag passes with at most :data:`MAX_WRONG_CELLS` wrong cells and a contrast of at least
    :data:`MIN_CONTRAST`.
    """
    k, b = bits.shape[0], bits.shape[1]
    ok = np.zeros(k, dtype=bool)
    square = np.array([[0.0, b], [b, b], [b, 0.0], [0.0, 0.0]])  # cell units, y down
    c = np.arange(b) + 0.5
    cx, cy = np.meshgrid(c, c)
    cells = np.stack([cx.ravel(), cy.ravel()], axis=1).reshape(-1, 1, 2)
    for i in range(k):  # one homography a tag
        H, _ = cv2.findHomography(square, quads[i])
        if H is None:
            continue
        at = cv2.perspectiveTransform(cells, H).reshape(b * b, 1, 2).astype(np.float32)
        v = cv2.remap(gray, at[..., 0], at[..., 1], cv2.INTER_LINEAR).reshape(-1).astype(float)
        lo, hi = np.percentile(v, [5, 95])
        if hi - lo < MIN_CONTRAST:
            continue
        wrong = np.count_nonzero((v > 0.5 * (lo + hi)) != bits[i].ravel())
        ok[i] = wrong <= MAX_WRONG_CELLS
    return ok


def _predict_tags(
    target: AprilGrid, found: IntArray, corners: FloatArray, missing: IntArray
) -> FloatArray:
    """Predicted corners (k, 4, 2) of ``missing`` tags from the refined corners (n, 4, 2) of
    the ``found`` ones: a homography fitted to the corners of the nearest found tags (on
    the grid), so lens distortion matters only locally. NaN where no prediction."""
    pts = target.points()[:, :2]
    pos = np.stack(np.divmod(found, target.tag_cols), axis=1).astype(float)
    out = np.full((missing.size, 4, 2), np.nan)
    for i, t in enumerate(missing):  # one small fit a missing tag
        d = np.linalg.norm(pos - np.array(divmod(int(t), target.tag_cols), dtype=float), axis=1)
        near = np.argsort(d, kind="stable")[:NEAR_TAGS]
        if near.size < 2 or d[near[0]] > 2.5:
            continue
        src = pts[target.tag_corner_ids(found[near]).reshape(-1)]
        dst = corners[near].reshape(-1, 2)
        good = np.all(np.isfinite(dst), axis=1)
        if np.count_nonzero(good) < 8:
            continue
        H, _ = cv2.findHomography(src[good], dst[good], 0)
        if H is None:
            continue
        tp = pts[target.tag_corner_ids(np.array([t])).reshape(-1)].reshape(-1, 1, 2)
        out[i] = cv2.perspectiveTransform(tp, H).reshape(4, 2)
    return out


def _detect_aprilgrid(gray: NDArray[np.uint8], target: AprilGrid) -> TargetDetection:
    # the tags' corners from their edges' lines (CORNER_REFINE_CONTOUR): where Kalibr's
    # squares touch a tag the contour's own corners can be bits off, beyond the windows
    detector = _detector(target.dictionary, KALIBR_BORDER_BITS, cv2.aruco.CORNER_REFINE_CONTOUR)
    quads, tag_ids, _ = detector.detectMarkers(gray)
    if tag_ids is None or len(tag_ids) == 0:
        return _empty()
    t = np.asarray(tag_ids, dtype=np.int64).reshape(-1)
    q = np.asarray(quads, dtype=float).reshape(-1, 4, 2)
    n_tags = target.tag_cols * target.tag_rows
    mine = t < n_tags
    t, q = t[mine], q[mine]
    if t.size == 0:
        return _empty()
    # ArUco's corners in Kalibr's order (bottom-left, bottom-right, top-right, top-left of
    # the tag as printed)
    q = q[:, KALIBR_CORNERS_FROM_ARUCO]
    tag_bits = _TAG36H11_BITS + 2 * KALIBR_BORDER_BITS  # tag36h11 in Kalibr's border: 10
    bit_px = _marker_side_px(q) / tag_bits
    px = _refine_junctions(gray, q.reshape(-1, 2), np.repeat(bit_px, 4))
    px = px.reshape(-1, 4, 2)
    # tags the detector missed (Kalibr's squares touch their corners): predicted from their
    # found neighbours, refined, and kept when their cells read as the expected tag
    h, w = gray.shape
    for _ in range(GROW_ROUNDS):
        missing = np.setdiff1d(np.arange(n_tags), t)
        if missing.size == 0:
            break
        pred = _predict_tags(target, t, px, missing)
        side = _marker_side_px(pred)
        bit_px = side / tag_bits
        edge = 2.0 * bit_px[:, None, None]  # two bits from the image's edges
        inside = np.all(
            np.isfinite(pred) & (pred >= edge) & (pred <= np.array([w - 1, h - 1]) - edge),
            axis=(1, 2),
        )
        inside &= side >= MIN_TAG_PX
        if not inside.any():
            break
        cand, pred = missing[inside], pred[inside]
        ref = _refine_junctions(gray, pred.reshape(-1, 2), np.repeat(bit_px[inside], 4))
        ref = ref.reshape(-1, 4, 2)
        good = np.all(np.isfinite(ref), axis=(1, 2))
        if good.any():
            cand, ref = cand[good], ref[good]
            good = _verify_tags(gray, ref, aprilgrid_tag_cells(cand))
        if not good.any():
            break
        t = np.concatenate([t, cand[good]])
        px = np.concatenate([px, ref[good]])
    ids = target.tag_corner_ids(t).reshape(-1)
    return _collect(ids, px.reshape(-1, 2))


def _detect_charuco(gray: NDArray[np.uint8], target: Charuco) -> TargetDetection:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    detector = cv2.aruco.CharucoDetector(
        target.board(), cv2.aruco.CharucoParameters(), params, cv2.aruco.RefineParameters()
    )
    corners, corner_ids, quads, _ = detector.detectBoard(gray)
    if corner_ids is None or len(corner_ids) == 0 or quads is None or len(quads) == 0:
        return _empty()
    ids = np.asarray(corner_ids, dtype=np.int64).reshape(-1)
    px = np.asarray(corners, dtype=float).reshape(-1, 2)
    # the white margin around a marker, in pixels, from the markers' mean size
    side = float(np.median(_marker_side_px(np.asarray(quads, dtype=float).reshape(-1, 4, 2))))
    margin = 0.5 * (target.square_length - target.marker_length) / target.marker_length * side
    return _collect(ids, _refine_junctions(gray, px, np.full(ids.size, margin)))


def detect_target(image: NDArray[np.generic], target: Target) -> TargetDetection:
    """The identified corners of ``target`` in one image.

    Parameters
    ----------
    image : ndarray, shape (h, w) or (h, w, 3)
        The image (grey, or BGR turned grey); 8-bit, or any numeric dtype (rescaled).
    target : Checkerboard, AprilGrid or Charuco

    Returns
    -------
    TargetDetection
        Corner ids and pixels (sub-pixel), empty when nothing of the target was found. A
        checkerboard is found whole or not at all (:func:`detect_checkerboard`).
    """
    gray = _gray(image)
    if isinstance(target, Checkerboard):
        c = detect_checkerboard(gray, target.cols, target.rows)
        if c is None:
            return _empty()
        return TargetDetection(np.arange(target.n_corners, dtype=np.int64), c.reshape(-1, 2))
    if isinstance(target, AprilGrid):
        return _detect_aprilgrid(gray, target)
    return _detect_charuco(gray, target)


def find_other_family(image: NDArray[np.generic], target: Target) -> str | None:
    """The family of the markers an image shows when they are not ``target``'s, or None.

    Tries one dictionary of each common family (ArUco 4x4 to 7x7 and original, AprilTag
    16h5, 25h9, 36h10, 36h11, ArUco MIP 36h12) except the target's own, with ArUco's
    one-bit black border (tag36h11 also with Kalibr's two-bit border), and returns the
    family name (e.g. ``"DICT_6X6"`` or ``"DICT_APRILTAG_36h11"``) with the most markers,
    if at least :data:`MIN_FAMILY_MARKERS`. A checkerboard target has no family: None.
    """
    if isinstance(target, Checkerboard):
        return None
    gray = _gray(image)
    own = _family_of(target.dictionary)
    best, n_best = None, MIN_FAMILY_MARKERS - 1
    for family, name in _FAMILIES.items():
        if family == own:
            continue
        n = 0
        for border in (1, KALIBR_BORDER_BITS) if name == AprilGrid.dictionary else (1,):
            _, ids, _ = _detector(name, border).detectMarkers(gray)
            n = max(n, 0 if ids is None else len(ids))
        if n > n_best:
            best, n_best = family, n
    return best


def pose_ready(points: NDArray[np.floating]) -> bool:
    """Whether a view's identified corners determine a pose.

    Parameters
    ----------
    points : ndarray, shape (k, 3)
        The seen corners in the target frame (metres, ``z = 0``).

    Returns
    -------
    bool
        At least :data:`MIN_POSE_CORNERS` corners, not (nearly) on one line: the second
        singular value of the centred points at least :data:`MIN_SPREAD` of the first.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)[:, :2]
    if p.shape[0] < MIN_POSE_CORNERS:
        return False
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    return bool(s[0] > 0 and s[1] >= MIN_SPREAD * s[0])
