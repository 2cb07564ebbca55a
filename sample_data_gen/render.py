"""Rendered image sequences of a synthetic two-camera ACS seeing checkerboards.

Each camera is a pinhole with OpenCV's radial-tangential distortion (``k1 k2 p1 p2 k3``).
A pixel's colour comes from the ray through it (distortion inverted once per camera on a
supersampled grid with ``cv2.undistortPointsIter``): the board plane if the ray hits the
board, else a cluttered far background fixed in the world. The checkerboard pattern is
area-averaged analytically (a box filter the size of the sample's footprint on the board)
on top of ``supersample`` x ``supersample`` samples a pixel, so edges and corners are
unbiased. Then lighting (gain, offset, a smooth gradient), Gaussian blur, Gaussian sensor
noise and 8-bit quantisation.

Board frame (as in :mod:`acs_cli` and OpenCV): origin at the first inner corner, x along a
row of ``cols`` corners, y along the ``rows`` rows, z into the board; corner ``k`` (row-major,
``cols`` a row, as ``cv2.findChessboardCorners`` orders them) is at
``(k % cols, k // cols, 0) * square``. The board has one white square of margin all round.

The three scenarios of the paper:

- ``overlap``: both cameras see one shared board (one world, the board's frame);
- ``fixed_joint``: the joint stays at one world point, both bodies turn about it; camera A
  sees board A and camera B sees board B (two boards fixed in one physical world);
- ``general``: the rig moves freely and bends; each camera sees its own board.

Each camera's world is its own board's frame (what ``acscal poses`` outputs), so
``T_world_cam`` of camera A is in world A (board A) and camera B's is in world B (board B);
``T_wb_wa`` relates them (the identity for ``overlap``).

Output: ``OUT/<scenario>/cam_a/img_00000.png``, ..., ``OUT/<scenario>/cam_b/...``,
``OUT/<scenario>/truth.yaml`` (kind ``render_truth``) and the true trajectories
``cam_a_truth.tum``, ``cam_b_truth.tum`` (timestamps ``index / 10`` s).

With ``target`` (an AprilGrid or a ChArUco, :data:`SCENE_TARGETS`) each board is that target,
drawn and warped by :mod:`sample_data_gen.target_render`; each camera's world is then its
target's frame, ``OUT/<scenario>/target.yaml`` describes it, and a view half out of the
image still shows identified corners (a partial view).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from acs_cli.core import se3
from acs_cli.core.targets import AprilGrid, Charuco
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.atomic import atomic_write_bytes
from acs_cli.io.target import target_to_mapping, write_target_yaml
from acs_cli.io.trajectory import write_tum

__all__ = [
    "RENDER_SCENARIOS",
    "SCENE_TARGETS",
    "Board",
    "Camera",
    "board_corners",
    "make_camera",
    "render_sample_set",
    "render_scenario",
    "render_view",
]

FloatArray = se3.FloatArray

#: Scenarios :func:`render_scenario` knows.
RENDER_SCENARIOS = ("overlap", "fixed_joint", "general")
TRUTH_KIND = "render_truth"
FPS = 10.0
#: Targets the size of the default checkerboard's printed area, whose tags a 640x480 view
#: from :func:`render_scenario`'s ``board_distance`` resolves (``--target aprilgrid``).
SCENE_TARGETS: dict[str, AprilGrid | Charuco] = {
    "aprilgrid": AprilGrid(4, 3, 0.045, 0.3),
    "charuco": Charuco(7, 5, 0.035, 0.026, "DICT_5X5_100"),
}

_WHITE = 0.8  # albedo of the white squares and margin
_BLACK = 0.07  # albedo of the black squares
_MAX_TRIES = 4000


# --------------------------------------------------------------------------- cameras


@dataclass(frozen=True)
class Camera:
    """A pinhole camera with radial-tangential distortion and its precomputed rays."""

    K: FloatArray
    dist: FloatArray
    size: tuple[int, int]  # (width, height)
    supersample: int
    rays: np.ndarray  # (H*s, W*s, 2) float32 normalised undistorted coordinates
    r_max: float  # largest normalised radius seen by the image (with some slack)

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]


def _sample_grid(size: tuple[int, int], s: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates of the ``s x s`` samples of every pixel (pixel centres at integers)."""
    w, h = size
    offs = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(w)[:, None] + offs[None, :]).ravel()
    ys = (np.arange(h)[:, None] + offs[None, :]).ravel()
    return np.meshgrid(xs, ys)


def _undistort(K: FloatArray, dist: FloatArray, pix: np.ndarray) -> np.ndarray:
    """Normalised coordinates ``(n, 2)`` of distorted pixels ``(n, 2)``, refined to ~1e-9 px."""
    pts = pix.reshape(-1, 1, 2).astype(np.float64)
    und = cv2.undistortPoints(pts, K, dist).reshape(-1, 2)
    # Newton steps on the forward model: cv2's fixed-point iteration is only approximate.
    k1, k2, p1, p2, k3 = dist
    target = (pix.reshape(-1, 2) - K[:2, 2]) / np.array([K[0, 0], K[1, 1]])
    target[:, 0] -= K[0, 1] / K[0, 0] * target[:, 1]
    x, y = und[:, 0].copy(), und[:, 1].copy()
    tx = np.ascontiguousarray(target[:, 0])
    ty = np.ascontiguousarray(target[:, 1])
    for _ in range(4):
        xx, yy, xy = x * x, y * y, x * y
        r2 = xx + yy
        rad = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d rad / d r2
        fx = x * rad + 2 * p1 * xy + p2 * (r2 + 2 * xx) - tx
        fy = y * rad + p1 * (r2 + 2 * yy) + 2 * p2 * xy - ty
        j11 = rad + 2 * xx * drad + 2 * p1 * y + 6 * p2 * x
        j12 = 2 * xy * drad + 2 * p1 * x + 2 * p2 * y
        j22 = rad + 2 * yy * drad + 6 * p1 * y + 2 * p2 * x
        det = j11 * j22 - j12 * j12
        x = x - (j22 * fx - j12 * fy) / det
        y = y - (j11 * fy - j12 * fx) / det
    return np.stack([x, y], axis=1)


#: Cameras built lately, by their parameters: a scenario's cameras are rebuilt for each of
#: its sequences, and a test process renders the same seeded cameras many times (each ray
#: map is a second of Newton steps over a million samples).
_CAMERAS: dict[tuple[bytes, bytes, tuple[int, int], int], Camera] = {}
_CAMERAS_KEPT = 8


def _build_camera(K: FloatArray, dist: FloatArray, size: tuple[int, int], s: int) -> Camera:
    key = (np.asarray(K, float).tobytes(), np.asarray(dist, float).tobytes(), tuple(size), s)
    cam = _CAMERAS.get(key)
    if cam is None:
        cam = _new_camera(K, dist, size, s)
        cam.rays.setflags(write=False)  # shared by every render of this camera
        if len(_CAMERAS) >= _CAMERAS_KEPT:
            _CAMERAS.pop(next(iter(_CAMERAS)))
        _CAMERAS[key] = cam
    return cam


def _new_camera(K: FloatArray, dist: FloatArray, size: tuple[int, int], s: int) -> Camera:
    gx, gy = _sample_grid(size, s)
    pix = np.stack([gx.ravel(), gy.ravel()], axis=1)
    rays = _undistort(K, dist, pix).astype(np.float32).reshape((*gx.shape, 2))
    w, h = size
    corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]])
    r_max = float(np.max(np.linalg.norm(_undistort(K, dist, corners), axis=1)))
    return Camera(K=K, dist=dist, size=size, supersample=s, rays=rays, r_max=1.2 * r_max)


def _monotonic(dist: FloatArray, r_max: float) -> bool:
    k1, k2, _p1, _p2, k3 = dist
    r = np.linspace(0.0, r_max, 200)
    r2 = r * r
    return bool(np.all(1 + 3 * k1 * r2 + 5 * k2 * r2**2 + 7 * k3 * r2**3 > 0.2))


def make_camera(
    rng: np.random.Generator, size: tuple[int, int] = (640, 480), supersample: int = 2
) -> Camera:
    """A random, realistic camera: focal 0.9-1.1 x width, principal point near the centre,
    ``k1`` in [-0.2, 0.1], small ``k2``, ``k3`` and tangential terms."""
    w, h = size
    for _ in range(100):
        fx = w * rng.uniform(0.9, 1.1)
        fy = fx * rng.uniform(0.995, 1.005)
        cx = (w - 1) / 2 + rng.uniform(-0.02, 0.02) * w
        cy = (h - 1) / 2 + rng.uniform(-0.02, 0.02) * h
        dist = np.array(
            [
                rng.uniform(-0.2, 0.1),
                rng.uniform(-0.05, 0.08),
                rng.uniform(-1e-3, 1e-3),
                rng.uniform(-1e-3, 1e-3),
                rng.uniform(-0.02, 0.02),
            ]
        )
        corner_r = np.hypot(w / 2, h / 2) / fx
        if _monotonic(dist, 1.6 * corner_r):
            break
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return _build_camera(K, dist, size, supersample)


# --------------------------------------------------------------------------- boards


@dataclass(frozen=True)
class Board:
    """A checkerboard of ``cols x rows`` inner corners, squares of ``square`` metres."""

    cols: int
    rows: int
    square: float

    @property
    def centre(self) -> FloatArray:
        return np.array([(self.cols - 1) / 2, (self.rows - 1) / 2, 0.0]) * self.square

    @property
    def size(self) -> float:
        """Diagonal of the printed area (squares plus margin), metres."""
        return float(np.hypot(self.cols + 3, self.rows + 3) * self.square)


def board_corners(board: Board) -> FloatArray:
    """``(cols*rows, 3)`` inner corners in the board frame, row-major (OpenCV's order)."""
    c, r = np.meshgrid(np.arange(board.cols), np.arange(board.rows))
    return np.stack([c.ravel(), r.ravel(), np.zeros(c.size)], axis=1) * board.square


def _outer_corners(board: Board) -> FloatArray:
    """Corners of every square (including the outer ones), board frame."""
    c, r = np.meshgrid(np.arange(-1, board.cols + 1), np.arange(-1, board.rows + 1))
    return np.stack([c.ravel(), r.ravel(), np.zeros(c.size)], axis=1) * board.square


def _board_area_points(board: Board, n: int = 24) -> FloatArray:
    """A dense grid over the printed area (squares and margin), board frame."""
    u = np.linspace(-2, board.cols + 1, n)
    v = np.linspace(-2, board.rows + 1, n)
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel(), np.zeros(uu.size)], axis=1) * board.square


def _project(cam: Camera, T_cam_board: FloatArray, pts: FloatArray) -> tuple[FloatArray, Any]:
    """Pixels of board points and a mask of those in front of the camera and inside the
    region the distortion model is valid for."""
    p = se3.transform_points(T_cam_board, pts)
    front = p[:, 2] > 1e-6
    xn = p[:, :2] / np.where(front, p[:, 2], 1.0)[:, None]
    ok = front & (np.linalg.norm(xn, axis=1) < cam.r_max)
    rvec = np.zeros(3)
    tvec = np.zeros(3)
    xyz = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
    uv, _ = cv2.projectPoints(xyz, rvec, tvec, cam.K, cam.dist)
    return uv.reshape(-1, 2), ok


def _inside(cam: Camera, uv: FloatArray, ok: Any, margin: float) -> Any:
    w, h = cam.size
    return (
        ok
        & (uv[:, 0] >= margin - 0.5)
        & (uv[:, 0] <= w - 0.5 - margin)
        & (uv[:, 1] >= margin - 0.5)
        & (uv[:, 1] <= h - 0.5 - margin)
    )


def classify_view(cam: Camera, board: Board, T_world_cam: FloatArray) -> tuple[str, int]:
    """``("full"|"partial"|"none", corners in view)`` of ``board`` (world = board frame).

    "full": every square corner (outer ones too) is at least 4 px inside the image; "none":
    no part of the printed board is in view; "partial" otherwise.
    """
    T_cb = se3.invert_transforms(T_world_cam)
    uv, ok = _project(cam, T_cb, board_corners(board))
    n_in = int(np.count_nonzero(_inside(cam, uv, ok, 0.0)))
    uv_o, ok_o = _project(cam, T_cb, _outer_corners(board))
    if np.all(_inside(cam, uv_o, ok_o, 4.0)):
        return "full", n_in
    uv_a, ok_a = _project(cam, T_cb, _board_area_points(board))
    if not np.any(_inside(cam, uv_a, ok_a, -1.0)):
        return "none", 0
    return "partial", n_in


# --------------------------------------------------------------------------- rendering


def _environment(rng: np.random.Generator, h: int = 1024) -> np.ndarray:
    """An equirectangular (h x 2h) cluttered grey texture: multi-scale noise and shapes."""
    w = 2 * h
    tex = np.full((h, w), 0.45, np.float32)
    for cells, amp in ((4, 0.18), (16, 0.12), (64, 0.08), (256, 0.04)):
        small = rng.normal(size=(cells, 2 * cells)).astype(np.float32)
        tex += amp * cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    for _ in range(300):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        sx, sy = int(rng.integers(5, 80)), int(rng.integers(5, 80))
        val = float(rng.uniform(0.1, 0.8))
        if rng.uniform() < 0.5:
            cv2.rectangle(tex, (x0, y0), (x0 + sx, y0 + sy), val, -1)
        else:
            cv2.circle(tex, (x0, y0), sx // 2, val, -1)
    tex = cv2.GaussianBlur(tex, (0, 0), 1.0)
    return np.clip(tex, 0.03, 0.95)


def _tri(u: np.ndarray) -> np.ndarray:
    """Antiderivative of the unit square wave (+1 on [0,1), -1 on [1,2), period 2)."""
    m = u - 2.0 * np.floor(0.5 * u) - 1.0
    np.abs(m, out=m)
    return 1.0 - m


def _filtered_square_wave_on(u: np.ndarray, w: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """The square wave times the indicator of ``[lo, hi]``, box-filtered over
    ``[u - w/2, u + w/2]``."""
    a = np.minimum(np.maximum(u - 0.5 * w, lo), hi)
    b = np.minimum(np.maximum(u + 0.5 * w, lo), hi)
    return (_tri(b) - _tri(a)) / w


def _filtered_box(u: np.ndarray, w: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Fraction of ``[u - w/2, u + w/2]`` inside ``[lo, hi]``."""
    a = np.maximum(u - 0.5 * w, lo)
    b = np.minimum(u + 0.5 * w, hi)
    return np.maximum(b - a, 0.0) / w


def _background(rays: np.ndarray, T_cam_world: FloatArray, env: np.ndarray) -> np.ndarray:
    """The far background (an environment map fixed in the world) along ``rays``."""
    x = rays[..., 0].astype(np.float64)
    y = rays[..., 1].astype(np.float64)
    R_wc = T_cam_world[:3, :3].T
    norm = np.sqrt(x * x + y * y + 1.0)
    dx = (R_wc[0, 0] * x + R_wc[0, 1] * y + R_wc[0, 2]) / norm
    dy = (R_wc[1, 0] * x + R_wc[1, 1] * y + R_wc[1, 2]) / norm
    dz = (R_wc[2, 0] * x + R_wc[2, 1] * y + R_wc[2, 2]) / norm
    eh, ew = env.shape
    mx = ((np.arctan2(dx, dz) / (2 * np.pi) + 0.5) * ew).astype(np.float32)
    my = ((np.arcsin(np.clip(dy, -1, 1)) / np.pi + 0.5) * (eh - 1)).astype(np.float32)
    return cv2.remap(env, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP).astype(np.float64)


def _albedo_chunk(
    rays: np.ndarray,
    T_cam_world: FloatArray,
    T_cam_board: FloatArray | None,
    board: Board,
    cam: Camera,
    env: np.ndarray,
) -> np.ndarray:
    """Albedo of the samples ``rays`` ``(m, n, 2)``: board where hit, environment elsewhere."""
    out = _background(rays[:: cam.supersample, :: cam.supersample], T_cam_world, env)
    s = cam.supersample
    out = np.repeat(np.repeat(out, s, axis=0), s, axis=1)
    x = rays[..., 0].astype(np.float64)
    y = rays[..., 1].astype(np.float64)
    if T_cam_board is None:
        return out
    R = T_cam_board[:3, :3]
    t = T_cam_board[:3, 3]
    n = R[:, 2]
    nt = float(n @ t)
    nd = n[0] * x + n[1] * y + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = nt / nd
    hit = np.isfinite(lam) & (lam > 0)
    lam = np.where(hit, lam, 0.0)
    sq = board.square
    r0, r1 = R[:, 0], R[:, 1]
    u = (lam * (r0[0] * x + r0[1] * y + r0[2]) - r0 @ t) / sq
    v = (lam * (r1[0] * x + r1[1] * y + r1[2]) - r1 @ t) / sq
    # only samples on or near the printed area (3 squares of slack for the footprint)
    sel = hit & (u > -5.0) & (u < board.cols + 4.0) & (v > -5.0) & (v < board.rows + 4.0)
    if not np.any(sel):
        return out
    x, y, u, v, lam, nd = x[sel], y[sel], u[sel], v[sel], lam[sel], nd[sel]
    # footprint of one sample on the board (squares): d(board)/d(ray) applied to one sample
    # step in normalised coordinates (distortion's local scale change is ignored: the box
    # filter is symmetric, so it only changes the edge sharpness, not the edge positions)
    a0 = r0[0] * x + r0[1] * y + r0[2]
    a1 = r1[0] * x + r1[1] * y + r1[2]
    wu = np.full_like(u, 1e-9)
    wv = np.full_like(v, 1e-9)
    for axis, f in ((0, cam.K[0, 0]), (1, cam.K[1, 1])):
        e = 1.0 / (s * f)
        ne = n[axis] * e
        wu += np.abs(lam * (r0[axis] * e - a0 * ne / nd)) / sq
        wv += np.abs(lam * (r1[axis] * e - a1 * ne / nd)) / sq
    wu = np.minimum(wu, 50.0)
    wv = np.minimum(wv, 50.0)
    # black fraction of the footprint: (I_u I_v + (sq_u I_u)(sq_v I_v)) / 2, with I the
    # inner (squares) area and sq the square wave; every factor depends on u or v alone,
    # so the separable box filter of each product is the product of the filtered factors.
    # The square at u in [-1, 0), v in [-1, 0) is black (square-wave product +1 there).
    iu = _filtered_box(u, wu, -1.0, board.cols)
    iv = _filtered_box(v, wv, -1.0, board.rows)
    su = _filtered_square_wave_on(u, wu, -1.0, board.cols)
    sv = _filtered_square_wave_on(v, wv, -1.0, board.rows)
    black = 0.5 * (iu * iv + su * sv)
    printed = _filtered_box(u, wu, -2.0, board.cols + 1.0) * _filtered_box(
        v, wv, -2.0, board.rows + 1.0
    )
    board_albedo = printed * _WHITE - black * (_WHITE - _BLACK)
    out[sel] = board_albedo + (1.0 - printed) * out[sel]
    return out


@dataclass(frozen=True)
class Photometry:
    """Per-image lighting, blur and noise."""

    gain: float
    offset: float
    gradient: tuple[float, float]
    blur_sigma: float
    noise_sigma: float


def _random_photometry(rng: np.random.Generator, blur: bool, noise_sigma: float) -> Photometry:
    ang = rng.uniform(0, 2 * np.pi)
    mag = rng.uniform(0.0, 0.25)
    sigma = float(rng.uniform(0.3, 1.0))  # drawn always: blur does not change other draws
    return Photometry(
        gain=float(rng.uniform(0.7, 1.05)),
        offset=float(rng.uniform(-6.0, 10.0)),
        gradient=(float(mag * np.cos(ang)), float(mag * np.sin(ang))),
        blur_sigma=sigma if blur else 0.0,
        noise_sigma=float(noise_sigma),
    )


def render_view(
    cam: Camera,
    T_world_cam: FloatArray,
    board: Board | None,
    T_world_board: FloatArray | None,
    env: np.ndarray,
    photometry: Photometry,
    rng: np.random.Generator,
    chunk_rows: int = 256,
) -> np.ndarray:
    """An 8-bit grey image ``(H, W)`` of ``board`` (at ``T_world_board``) from ``T_world_cam``."""
    T_cam_world = se3.invert_transforms(T_world_cam)
    T_cam_board = None
    if board is not None and T_world_board is not None:
        T_cam_board = T_cam_world @ T_world_board
    s = cam.supersample
    w, h = cam.size
    rows = []
    step = max(s, (chunk_rows // s) * s)
    for r0 in range(0, h * s, step):
        chunk = cam.rays[r0 : r0 + step]
        alb = _albedo_chunk(chunk, T_cam_world, T_cam_board, board or Board(1, 1, 1.0), cam, env)
        m = alb.shape[0] // s
        rows.append(alb.reshape(m, s, w, s).mean(axis=(1, 3)))
    return apply_photometry(np.concatenate(rows, axis=0), photometry, rng)


def apply_photometry(
    albedo: np.ndarray, photometry: Photometry, rng: np.random.Generator
) -> np.ndarray:
    """The 8-bit image ``(H, W)`` of an albedo map ``(H, W)`` (0-1): lighting (gain, offset,
    gradient), Gaussian blur, Gaussian noise and quantisation."""
    h, w = albedo.shape
    xs = (np.arange(w) - (w - 1) / 2) / w
    ys = (np.arange(h) - (h - 1) / 2) / h
    gx, gy = photometry.gradient
    light = photometry.gain * (1.0 + 2.0 * (gx * xs[None, :] + gy * ys[:, None]))
    img = 255.0 * albedo * light + photometry.offset
    if photometry.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), photometry.blur_sigma)
    if photometry.noise_sigma > 0:
        img = img + rng.normal(scale=photometry.noise_sigma, size=img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- poses


def _rot(axis: FloatArray, deg: float) -> FloatArray:
    axis = np.asarray(axis, float)
    return se3.matrix_from_rotvec(axis / np.linalg.norm(axis) * np.radians(deg))


def _look_at(P: FloatArray, target: FloatArray, roll_deg: float) -> FloatArray:
    """``R_world_cam`` of a camera at ``P`` looking at ``target``, board-up, rolled."""
    z = target - P
    z = z / np.linalg.norm(z)
    x = np.array([z[2], 0.0, -z[0]])  # (0, 1, 0) x z, without np.cross's overhead
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.array([z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]])
    return np.stack([x, y, z], axis=1) @ _rot(np.array([0.0, 0.0, 1.0]), roll_deg)


def _look_at_about_pivot(
    J: FloatArray, o: FloatArray, target: FloatArray, roll_deg: float
) -> FloatArray | None:
    """``T_world_cam`` with the body point ``o`` (camera frame) at world ``J``, looking at
    ``target``; ``None`` if the target is too close to the pivot."""
    if np.linalg.norm(target - J) < 1.5 * np.linalg.norm(o):
        return None
    R = _look_at(J, target, roll_deg)
    for _ in range(60):
        P = J - R @ o
        R = _look_at(P, target, roll_deg)
    return se3.transforms_from_rt(R, J - R @ o)


def _view_target(
    rng: np.random.Generator, cam: Camera, board: Board, dist: float, kind: str
) -> FloatArray:
    """A point to look at (board frame) for a view of ``kind``."""
    c = board.centre
    half_fov = 0.5 * cam.width / cam.K[0, 0]
    ang = rng.uniform(0, 2 * np.pi)
    direc = np.array([np.cos(ang), np.sin(ang), 0.0])
    if kind == "full":
        off = rng.uniform(0, 0.12) * board.size
    elif kind == "partial":
        off = dist * half_fov * rng.uniform(0.8, 1.3)
    else:  # turned away sideways (the environment map is least distorted there)
        ang = rng.uniform(-0.4, 0.4) + (np.pi if rng.uniform() < 0.5 else 0.0)
        direc = np.array([np.cos(ang), np.sin(ang), 0.0])
        off = dist * half_fov * rng.uniform(3.0, 5.0) + board.size
    return c + off * direc


def _free_pose(
    rng: np.random.Generator,
    cam: Camera,
    board: Board,
    dist: float,
    kind: str,
    max_tilt_deg: float,
) -> FloatArray:
    """A camera pose (board frame) at ~``dist`` from the board, tilted up to ``max_tilt_deg``."""
    axis_ang = rng.uniform(0, 2 * np.pi)
    axis = np.array([np.cos(axis_ang), np.sin(axis_ang), 0.0])
    tilt = np.degrees(np.arccos(rng.uniform(np.cos(np.radians(max_tilt_deg)), 1.0)))
    d = _rot(axis, tilt) @ np.array([0.0, 0.0, -1.0])
    P = board.centre + dist * rng.uniform(0.85, 1.15) * d
    R = _look_at(P, _view_target(rng, cam, board, dist, kind), rng.uniform(-30, 30))
    return se3.transforms_from_rt(R, P)


def _kinds(rng: np.random.Generator, n: int, partial: float, missing: float) -> list[str]:
    """Per-frame intended visibility: frame 0 is always full."""
    kinds = ["full"] * n
    if n <= 1:
        return kinds
    n_missing = round(missing * n)
    n_partial = round(partial * n)
    idx = rng.permutation(np.arange(1, n))
    for i in idx[:n_missing]:
        kinds[int(i)] = "none"
    for i in idx[n_missing : n_missing + n_partial]:
        kinds[int(i)] = "partial"
    return kinds


@dataclass(frozen=True)
class Rig:
    """The joint (``o_a``, ``o_b``) and the rest relative rotation ``R0 = R_a_b``."""

    o_a: FloatArray
    o_b: FloatArray
    R0: FloatArray


@dataclass
class Layout:
    """A scenario's rig, boards and rest geometry (everything in world A = board A)."""

    rig: Rig
    board_a: Board
    board_b: Board
    T_wa_wb: FloatArray  # board B's frame in world A
    joint_wa: FloatArray  # joint at rest (fixed for fixed_joint), world A


def _non_overlap_layout(
    rng: np.random.Generator, board: Board, board_distance: float, joint_distance: float
) -> Layout:
    """Cameras looking in different directions (for fixed_joint and general)."""
    while True:
        sgn = 1.0 if rng.uniform() < 0.5 else -1.0
        yaw = sgn * rng.uniform(100.0, 150.0)
        R0 = _rot(np.array([0.0, 1.0, 0.0]), yaw) @ se3.matrix_from_rotvec(
            rng.normal(scale=np.radians(6.0), size=3)
        )
        da = np.array(
            [sgn * rng.uniform(0.5, 1.0), rng.uniform(-0.3, 0.3), rng.uniform(-0.6, -0.1)]
        )
        db = np.array(
            [-sgn * rng.uniform(0.5, 1.0), rng.uniform(-0.3, 0.3), rng.uniform(-0.6, -0.1)]
        )
        o_a = joint_distance * rng.uniform(0.9, 1.1) * da / np.linalg.norm(da)
        o_b = joint_distance * rng.uniform(0.9, 1.1) * db / np.linalg.norm(db)
        P_a = board.centre - np.array([0.0, 0.0, board_distance])
        J = P_a + o_a
        P_b = J - R0 @ o_b
        if np.linalg.norm(P_a - P_b) > 0.2 * joint_distance:
            break
    c_b = P_b + board_distance * R0[:, 2]
    R_wa_wb = R0 @ se3.matrix_from_rotvec(rng.normal(scale=np.radians(8.0), size=3))
    t = c_b - R_wa_wb @ board.centre
    return Layout(Rig(o_a, o_b, R0), board, board, se3.transforms_from_rt(R_wa_wb, t), J)


def _overlap_layout(
    rng: np.random.Generator, board: Board, board_distance: float, joint_distance: float
) -> Layout:
    """Two cameras side by side converging on one board, the joint behind between them."""
    c = board.centre
    h = 0.6 * joint_distance
    gamma = np.degrees(np.arcsin(min(0.9, h / board_distance)))
    y_ax = np.array([0.0, 1.0, 0.0])
    P_a = c + _rot(y_ax, gamma) @ np.array([0.0, 0.0, -board_distance])
    P_b = c + _rot(y_ax, -gamma) @ np.array([0.0, 0.0, -board_distance])
    R_a = _look_at(P_a, c, rng.uniform(-5, 5))
    R_b = _look_at(P_b, c, rng.uniform(-5, 5))
    M = 0.5 * (P_a + P_b)
    half = 0.5 * np.linalg.norm(P_a - P_b)
    rest = np.sqrt(max(joint_distance**2 - half**2, 1e-6))
    back = (M - c) / np.linalg.norm(M - c)
    phi = rng.uniform(-0.6, 0.6)
    J = M + rest * (np.cos(phi) * back + np.sin(phi) * np.array([0.0, -1.0, 0.0]))
    rig = Rig(R_a.T @ (J - P_a), R_b.T @ (J - P_b), R_a.T @ R_b)
    return Layout(rig, board, board, np.eye(4), J)


def _view_ok(cam: Camera, board: Board, T_world_cam: FloatArray, kind: str) -> bool:
    """Is the view of the intended kind? A partial view shows 20-80 % of the corners."""
    got, n_in = classify_view(cam, board, T_world_cam)
    if got != kind:
        return False
    if kind == "full":  # not too oblique: the board's normal within 50 deg of the view ray
        ray = board.centre - T_world_cam[:3, 3]
        if ray[2] < np.cos(np.radians(50.0)) * np.linalg.norm(ray):
            return False
    return kind != "partial" or 0.2 <= n_in / (board.cols * board.rows) <= 0.8


def _rotation_angle_deg(R: FloatArray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def _sample_motion(
    rng: np.random.Generator,
    scenario: str,
    layout: Layout,
    cams: tuple[Camera, Camera],
    kinds: tuple[list[str], list[str]],
    board_distance: float,
    max_tilt_deg: float = 40.0,
    max_articulation_deg: float = 80.0,
) -> tuple[FloatArray, FloatArray]:
    """``T_wa_a`` and ``T_wb_b`` stacks ``(n, 4, 4)`` with the requested visibilities."""
    rig = layout.rig
    T_wb_wa = se3.invert_transforms(layout.T_wa_wb)
    n = len(kinds[0])
    T_a = np.zeros((n, 4, 4))
    T_b = np.zeros((n, 4, 4))
    for i in range(n):
        ka, kb = kinds[0][i], kinds[1][i]
        for _ in range(_MAX_TRIES):
            if scenario == "fixed_joint":
                tgt = _view_target(rng, cams[0], layout.board_a, board_distance, ka)
                Ta = _look_at_about_pivot(layout.joint_wa, rig.o_a, tgt, rng.uniform(-35, 35))
                if Ta is None:
                    continue
            else:
                Ta = _free_pose(rng, cams[0], layout.board_a, board_distance, ka, max_tilt_deg)
            J_wb = se3.transform_points(T_wb_wa @ Ta, rig.o_a)
            tgt_b = _view_target(rng, cams[1], layout.board_b, board_distance, kb)
            Tb = _look_at_about_pivot(J_wb, rig.o_b, tgt_b, rng.uniform(-35, 35))
            if Tb is None:
                continue
            T_a_b = se3.invert_transforms(Ta) @ layout.T_wa_wb @ Tb
            Q = T_a_b[:3, :3] @ rig.R0.T
            if _rotation_angle_deg(Q) > max_articulation_deg:
                continue
            dist_b = np.linalg.norm(Tb[:3, 3] - layout.board_b.centre)
            if not 0.6 * board_distance < dist_b < 1.6 * board_distance:
                continue
            if not _view_ok(cams[0], layout.board_a, Ta, ka):
                continue
            if not _view_ok(cams[1], layout.board_b, Tb, kb):
                continue
            T_a[i], T_b[i] = Ta, Tb
            break
        else:
            raise RuntimeError(
                f"could not place frame {i} ({ka}/{kb}) in scenario {scenario}; "
                "try another seed, a smaller board or a larger board distance"
            )
    return T_a, T_b


# --------------------------------------------------------------------------- writing


def _encode_png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    if not ok:  # pragma: no cover - cv2 failure
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def _parse_scenario(scenario: str) -> int:
    if scenario not in RENDER_SCENARIOS:
        raise ValueError(
            f"unknown scenario {scenario!r}; choose one of {', '.join(RENDER_SCENARIOS)}"
        )
    return RENDER_SCENARIOS.index(scenario)


def render_scenario(
    out_dir: str | Path,
    scenario: str,
    *,
    seed: int = 0,
    frames: int = 20,
    size: tuple[int, int] = (640, 480),
    board: tuple[int, int] = (9, 6),
    square: float = 0.025,
    board_distance: float = 0.6,
    joint_distance: float = 0.25,
    blur: bool = True,
    noise_sigma: float = 2.0,
    partial_fraction: float = 0.1,
    missing_fraction: float = 0.05,
    supersample: int = 2,
    target: AprilGrid | Charuco | None = None,
) -> Path:
    """Render one scenario into ``out_dir / scenario`` and return that folder.

    Parameters
    ----------
    out_dir : str or Path
        Parent folder; ``<scenario>/cam_a``, ``<scenario>/cam_b`` and
        ``<scenario>/truth.yaml`` are written under it.
    scenario : {"overlap", "fixed_joint", "general"}
        See the module documentation.
    seed : int
        Fixes the cameras (the same for every scenario of the seed), geometry, motion,
        lighting and noise. ``fixed_joint`` and ``general`` share one rig and one pair of
        boards (a joint found on ``fixed_joint`` serves ``general``); ``overlap`` has its
        own rig, whose cameras converge on one board.
    frames : int
        Images per camera.
    size : (width, height)
        Image size in pixels.
    board : (cols, rows)
        Inner corners of the checkerboard(s).
    square : float
        Square size, metres.
    board_distance : float
        Typical camera-to-board distance, metres.
    joint_distance : float
        Typical ``|o_a|``, ``|o_b|``, metres.
    blur : bool
        Random Gaussian blur (sigma 0.3-1.0 px) per image.
    noise_sigma : float
        Gaussian sensor noise, grey levels.
    partial_fraction, missing_fraction : float
        Fractions of each camera's frames with the board half out of view and out of view
        (frame 0 is always a full view).
    supersample : int
        Samples per pixel along each axis (on top of analytic area-averaging).
    target : AprilGrid or Charuco, optional
        Film this target instead of the checkerboard (``board`` and ``square`` are then
        unused): drawn and warped by :mod:`sample_data_gen.target_render`, the cameras
        placed about the checkerboard standing in for it
        (:func:`sample_data_gen.target_render.board_proxy`). Each camera's world is its
        target's frame; ``target.yaml`` (for ``--target``) is written beside the truth, and
        a partial view keeps the target's corners in the image identified.
    """
    k = _parse_scenario(scenario)
    w, h = (int(v) for v in size)
    cols, rows = (int(v) for v in board)
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    if w < 16 or h < 16:
        raise ValueError(f"image size {w}x{h} is too small")
    if cols < 2 or rows < 2 or not square > 0:
        raise ValueError("the board needs at least 2x2 inner corners and a positive square")
    if not (board_distance > 0 and joint_distance > 0):
        raise ValueError("board and joint distances must be positive")
    if not (
        0 <= partial_fraction and 0 <= missing_fraction and partial_fraction + missing_fraction < 1
    ):
        raise ValueError("partial and missing fractions must be >= 0 and sum to less than 1")
    if noise_sigma < 0 or supersample < 1:
        raise ValueError("noise_sigma must be >= 0 and supersample >= 1")
    t0 = time.perf_counter()
    cams = (
        make_camera(np.random.default_rng([seed, 10, 0]), (w, h), supersample),
        make_camera(np.random.default_rng([seed, 10, 1]), (w, h), supersample),
    )
    # imported here: target_render builds on this module
    from sample_data_gen.target_render import (
        board_proxy,
        classify_target_view,
        render_target_frame,
        target_texture,
    )

    the_board = Board(cols, rows, float(square))
    T_target_board: FloatArray = np.eye(4)
    if target is not None:
        the_board, T_target_board = board_proxy(target)
        texture = target_texture(target)
    if scenario == "overlap":
        layout = _overlap_layout(
            np.random.default_rng([seed, 21]), the_board, board_distance, joint_distance
        )
    else:
        layout = _non_overlap_layout(
            np.random.default_rng([seed, 20]), the_board, board_distance, joint_distance
        )
    rng = np.random.default_rng([seed, 30, k])
    kinds = (
        _kinds(rng, frames, partial_fraction, missing_fraction),
        _kinds(rng, frames, partial_fraction, missing_fraction),
    )
    T_a, T_b = _sample_motion(rng, scenario, layout, cams, kinds, board_distance)
    T_wa_env: FloatArray = np.eye(4)
    if target is not None:  # every world from the proxy board's frame to the target's
        T_a, T_b = T_target_board @ T_a, T_target_board @ T_b
        layout = replace(
            layout,
            T_wa_wb=T_target_board @ layout.T_wa_wb @ se3.invert_transforms(T_target_board),
            joint_wa=se3.transform_points(T_target_board, layout.joint_wa),
        )
        T_wa_env = T_target_board
    T_wb_wa = se3.invert_transforms(layout.T_wa_wb)
    envs = _environment(np.random.default_rng([seed, 40, k]))
    # the environment is fixed in world A; express B's poses in world A for it
    out = Path(out_dir) / scenario
    photos: dict[str, list[Photometry]] = {"cam_a": [], "cam_b": []}
    visibility: dict[str, list[str]] = {"cam_a": [], "cam_b": []}
    n_in_view: dict[str, list[int]] = {"cam_a": [], "cam_b": []}
    img_rng = np.random.default_rng([seed, 50, k])
    t_render = 0.0
    for name, cam, T_wc, T_w_env in (
        ("cam_a", cams[0], T_a, T_wa_env),
        ("cam_b", cams[1], T_b, T_wb_wa @ T_wa_env),
    ):
        for i in range(frames):
            ph = _random_photometry(img_rng, blur, noise_sigma)
            tr = time.perf_counter()
            if target is None:
                T_env_cam = se3.invert_transforms(T_w_env) @ T_wc[i]
                # render in the environment's frame: the board is at inv(T_w_env) in it
                T_env_board = se3.invert_transforms(T_w_env)
                img = render_view(cam, T_env_cam, the_board, T_env_board, envs, ph, img_rng)
            else:
                img = render_target_frame(
                    cam, T_wc[i], texture, envs, ph, img_rng, T_world_env=T_w_env
                )
            t_render += time.perf_counter() - tr
            atomic_write_bytes(out / name / f"img_{i:05d}.png", _encode_png(img))
            if target is None:
                kind, n_in = classify_view(cam, the_board, T_wc[i])
            else:
                kind, n_in = classify_target_view(cam, target, T_wc[i])
            photos[name].append(ph)
            visibility[name].append(kind)
            n_in_view[name].append(n_in)
    stamps = np.arange(frames) / FPS
    write_tum(out / "cam_a_truth.tum", stamps, T_a)
    write_tum(out / "cam_b_truth.tum", stamps, T_b)
    T_a_b = np.einsum("nij,jk,nkl->nil", se3.invert_transforms(T_a), layout.T_wa_wb, T_b)
    body = _truth_body(
        scenario=scenario,
        seed=seed,
        frames=frames,
        cams=cams,
        board=the_board,
        layout=layout,
        T_a=T_a,
        T_b=T_b,
        T_a_b=T_a_b,
        visibility=visibility,
        n_in_view=n_in_view,
        photos=photos,
        supersample=supersample,
        render_seconds=t_render / (2 * frames),
        total_seconds=time.perf_counter() - t0,
        target=target,
    )
    shown = f"board {cols}x{rows} x {square} m" if target is None else target.short()
    header = make_header(
        TRUTH_KIND,
        inputs={},
        method=(
            f"rendered synthetic ACS (sample_data_gen.render): scenario {scenario}, seed {seed}, "
            f"{frames} frames, {w}x{h}, {shown}"
        ),
        units={"length": "metres", "angles": "deg", "intensity": "grey levels (0-255)"},
        frames={
            "cam_a.T_world_cam": "camera A in world A (board A's frame)",
            "cam_b.T_world_cam": "camera B in world B (board B's frame)",
            "T_a_b": "maps b to a, per frame",
            "relative_pose.T_b_a": "maps a to b at the reference instant (paper's H_BA)",
            "joint.position_in_a": "a",
            "joint.position_in_b": "b",
            "joint.position_in_world_a": "world_a",
            "joint.position_in_world_b": "world_b",
            "T_wb_wa": "maps world_a to world_b",
            "boards.board_b.T_world_a_board": "board B's frame in world A",
        },
    )
    if target is not None:
        header["frames"]["boards"] = "each board is the target, in its frame (world_a, world_b)"
        write_target_yaml(out / "target.yaml", target)
    write_yaml_artifact(out / "truth.yaml", header, body)
    return out


def _truth_body(
    *,
    scenario: str,
    seed: int,
    frames: int,
    cams: tuple[Camera, Camera],
    board: Board,
    layout: Layout,
    T_a: FloatArray,
    T_b: FloatArray,
    T_a_b: FloatArray,
    visibility: dict[str, list[str]],
    n_in_view: dict[str, list[int]],
    photos: dict[str, list[Photometry]],
    supersample: int,
    render_seconds: float,
    total_seconds: float,
    target: AprilGrid | Charuco | None = None,
) -> dict[str, Any]:
    T_wb_wa = se3.invert_transforms(layout.T_wa_wb)
    T_b_a0 = se3.invert_transforms(T_a_b[0])
    board_doc: dict[str, Any] = {
        "cols": board.cols,
        "rows": board.rows,
        "square": board.square,
        "margin_squares": 1,
        "corner_order": "row-major, cols a row: corner k at (k % cols, k // cols, 0) * square",
    }
    if target is not None:
        board_doc = {
            "target": target_to_mapping(target),
            "short": target.short(),
            "file": "target.yaml",
        }
    joint: dict[str, Any] = {
        "position_in_a": layout.rig.o_a,
        "position_in_b": layout.rig.o_b,
    }
    if scenario == "fixed_joint":
        joint["position_in_world_a"] = layout.joint_wa
        joint["position_in_world_b"] = se3.transform_points(T_wb_wa, layout.joint_wa)

    def cam_doc(name: str, cam: Camera, T: FloatArray) -> dict[str, Any]:
        return {
            "model": "pinhole-radtan",
            "image_size": [cam.width, cam.height],
            "K": cam.K,
            "dist": cam.dist,
            "dist_order": "k1 k2 p1 p2 k3 (OpenCV)",
            "images": f"{name}/img_{{index:05d}}.png",
            "truth_trajectory": f"{name}_truth.tum",
            "world": "world_a (board A)" if name == "cam_a" else "world_b (board B)",
            "visibility": visibility[name],
            "corners_in_view": n_in_view[name],
            "T_world_cam": T,
            "blur_sigma_px": [p.blur_sigma for p in photos[name]],
        }

    shared = scenario == "overlap"
    return {
        "scenario": scenario,
        "seed": int(seed),
        "n_frames": int(frames),
        "image_size": [cams[0].width, cams[0].height],
        "fps": FPS,
        "timestamps": "frame index / fps (the index is in the file name)",
        "boards": {
            "shared": shared,
            "board_a": {**board_doc, "T_world_a_board": np.eye(4)},
            "board_b": {**board_doc, "T_world_a_board": layout.T_wa_wb},
        },
        "cam_a": cam_doc("cam_a", cams[0], T_a),
        "cam_b": cam_doc("cam_b", cams[1], T_b),
        "joint": joint,
        "rest_rotation_R_a_b": layout.rig.R0,
        "relative_pose": {
            "reference": 0,
            "T_b_a": T_b_a0,
            "rpy_deg": se3.rpy_deg_from_matrix(T_a_b[0][:3, :3]),
            "translation_b_in_a": T_a_b[0][:3, 3],
        },
        "T_a_b": T_a_b,
        "T_wb_wa": T_wb_wa,
        "render": {
            "supersample": supersample,
            "anti_aliasing": "analytic box filter of the sample footprint + supersampling",
            "noise_sigma": photos["cam_a"][0].noise_sigma if photos["cam_a"] else 0.0,
            "seconds_per_image": round(render_seconds, 4),
            "seconds_total": round(total_seconds, 2),
        },
    }


def render_sample_set(
    out_dir: str | Path,
    seed: int = 0,
    size: tuple[int, int] = (640, 480),
    frames: int = 20,
    **kwargs: Any,
) -> dict[str, Path]:
    """Render the three scenarios under ``out_dir`` (one folder each); returns them by name."""
    return {
        sc: render_scenario(out_dir, sc, seed=seed, size=size, frames=frames, **kwargs)
        for sc in RENDER_SCENARIOS
    }
