"""Rendered image sequences of one camera filming an AprilGrid or a ChArUco target.

The target is drawn as an image (Kalibr's AprilGrid as Kalibr prints it: the tags of
:func:`acs_cli.core.targets.aprilgrid_tag_cells`, from ``cv2.aruco``'s codes, with their
two-bit black border, and the black squares between the tags; ChArUco with
``CharucoBoard.generateImage``) at a resolution where every edge falls on a texel boundary,
then warped into each frame by the plane's ray mapping (a homography, and the lens'
distortion) of the renderer of :mod:`sample_data_gen.render`: each of ``supersample x
supersample`` samples a pixel takes the exact mean of the target image over its footprint
on the plane (a box, from an integral image of the texels), so edges and corners are
unbiased. The camera, the background, lighting, blur, noise and quantisation are those of
that renderer.

Half the frames show the whole target, the other half 30-70 % of its corners.

Output (``render_target_sequence``): ``OUT/images/img_00000.png`` ...,
``OUT/target.yaml`` (the target, for ``--target``), ``OUT/truth.yaml`` (kind
``target_render_truth``: intrinsics, each frame's ``T_world_cam`` with world = the target's
frame, visible fraction) and ``OUT/truth_corners.npz``: ``corners`` (n, m, 2) the true
projection of every target corner in every frame (pixels, NaN outside the image; column
``j`` = corner id ``j``) and ``board_points`` (m, 3) metres.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from acs_cli.core import se3
from acs_cli.core.targets import ARUCO_DICTIONARIES, AprilGrid, Charuco, aprilgrid_tag_cells
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.atomic import atomic_path, atomic_write_bytes
from acs_cli.io.target import target_to_mapping, write_target_yaml
from sample_data_gen.render import (
    _BLACK,
    _WHITE,
    Board,
    Camera,
    _background,
    _environment,
    _random_photometry,
    apply_photometry,
    make_camera,
)

__all__ = [
    "TARGET_KINDS",
    "TargetTexture",
    "board_proxy",
    "classify_target_view",
    "default_target",
    "project_corners",
    "render_target_frame",
    "render_target_sequence",
    "target_texture",
]

FloatArray = se3.FloatArray
#: The targets :func:`render_target_sequence` renders.
TARGET_KINDS = ("aprilgrid", "charuco")
TRUTH_KIND = "target_render_truth"
#: White margin around the printed pattern, in marker bits.
MARGIN_BITS = 2
_MAX_TRIES = 4000


@dataclass(frozen=True)
class TargetTexture:
    """A target as an image on its plane.

    Attributes
    ----------
    albedo : ndarray, shape (H, W)
        Albedo of each texel (0-1), margin included.
    integral : ndarray, shape (H + 1, W + 1)
        ``integral[i, j]`` = sum of ``albedo[:i, :j]`` (texel units).
    texel : float
        Side of a texel, metres.
    x0, y0 : float
        Target-frame coordinates (metres) of the texture's top-left corner.
    y_down : bool
        Whether the target's y axis runs down the texture (ChArUco) or up (AprilGrid).
    """

    albedo: np.ndarray
    integral: np.ndarray
    texel: float
    x0: float
    y0: float
    y_down: bool

    def uv(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Texture coordinates (texels from the top-left corner) of target points (metres)."""
        u = (x - self.x0) / self.texel
        v = ((y - self.y0) if self.y_down else (self.y0 - y)) / self.texel
        return u, v


def _texels_per_bit(length_in_bits: Fraction, limit: int = 64) -> int:
    """The fewest texels a marker bit with ``length_in_bits`` a whole number of texels."""
    n = length_in_bits.denominator
    if n > limit:
        raise ValueError(f"no texel grid of at most {limit} texels a bit fits {length_in_bits}")
    return n


def _with_integral(
    img: np.ndarray, texel: float, x0: float, y0: float, y_down: bool
) -> TargetTexture:
    albedo = _BLACK + (_WHITE - _BLACK) * (np.asarray(img, float) / 255.0)
    integral = np.zeros((albedo.shape[0] + 1, albedo.shape[1] + 1))
    integral[1:, 1:] = albedo.cumsum(axis=0).cumsum(axis=1)
    return TargetTexture(albedo, integral, texel, x0, y0, y_down)


def target_texture(target: AprilGrid | Charuco) -> TargetTexture:
    """The target drawn on a texel grid its edges fall on exactly (see the module
    documentation).

    Raises
    ------
    ValueError
        A geometry whose ratios need more than 64 texels a marker bit.
    """
    ratio_limit = 10**6
    if isinstance(target, AprilGrid):
        cells = aprilgrid_tag_cells(np.arange(target.tag_cols * target.tag_rows))
        bits = cells.shape[1]  # as Kalibr prints a tag: border included
        gap_bits = Fraction(target.spacing).limit_denominator(ratio_limit) * bits
        n = _texels_per_bit(gap_bits)  # the gap a whole number of texels
        tag = bits * n
        gap = int(gap_bits * n)
        margin = MARGIN_BITS * n
        pitch = tag + gap
        w = target.tag_cols * pitch + gap + 2 * margin
        h = target.tag_rows * pitch + gap + 2 * margin
        img = np.full((h, w), 255, np.uint8)
        for r in range(target.tag_rows + 1):  # Kalibr's squares between the tags' corners
            for c in range(target.tag_cols + 1):
                y = h - margin - r * pitch - gap
                x = margin + c * pitch
                img[y : y + gap, x : x + gap] = 0
        for t in range(target.tag_cols * target.tag_rows):
            r, c = divmod(t, target.tag_cols)
            x = margin + gap + c * pitch
            y = h - margin - gap - r * pitch - tag
            img[y : y + tag, x : x + tag] = np.where(np.kron(cells[t], np.ones((n, n))), 255, 0)
        texel = target.tag_size / tag
        # tag 0's bottom-left corner (the origin) is at texel (margin + gap, h - margin - gap)
        return _with_integral(
            img, texel, -(margin + gap) * texel, (h - margin - gap) * texel, y_down=False
        )
    d = cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARIES[target.dictionary])
    bits = int(d.markerSize) + 2
    ratio = Fraction(target.square_length / target.marker_length).limit_denominator(ratio_limit)
    # the white margin around a marker, so the square too, a whole number of texels
    n = _texels_per_bit((ratio - 1) * bits / 2)
    sq = ratio * bits * n
    square = int(sq)
    margin = MARGIN_BITS * n
    board_img = target.board().generateImage(
        (target.squares_x * square, target.squares_y * square), marginSize=0, borderBits=1
    )
    img = np.full((board_img.shape[0] + 2 * margin, board_img.shape[1] + 2 * margin), 255, np.uint8)
    img[margin:-margin, margin:-margin] = board_img
    texel = target.square_length / square
    return _with_integral(img, texel, -margin * texel, -margin * texel, y_down=True)


def _box_mean(tex: TargetTexture, u: np.ndarray, v: np.ndarray, wu: np.ndarray,
              wv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Mean albedo over the boxes ``[u +- wu/2] x [v +- wv/2]`` (texels) clipped to the
    texture, and the fraction of each box on it."""
    h, w = tex.albedo.shape
    u0 = np.clip(u - 0.5 * wu, 0.0, w)
    u1 = np.clip(u + 0.5 * wu, 0.0, w)
    v0 = np.clip(v - 0.5 * wv, 0.0, h)
    v1 = np.clip(v + 0.5 * wv, 0.0, h)
    S = tex.integral

    def F(uu: np.ndarray, vv: np.ndarray) -> np.ndarray:
        # the integral of a piecewise-constant image is bilinear in each texel: exact
        j = np.minimum(uu.astype(np.int64), w - 1)
        i = np.minimum(vv.astype(np.int64), h - 1)
        a = uu - j
        b = vv - i
        return (
            S[i, j] * (1 - a) * (1 - b)
            + S[i, j + 1] * a * (1 - b)
            + S[i + 1, j] * (1 - a) * b
            + S[i + 1, j + 1] * a * b
        )

    inside = F(u1, v1) - F(u0, v1) - F(u1, v0) + F(u0, v0)
    area = (u1 - u0) * (v1 - v0)
    frac = area / (wu * wv)
    mean = np.where(area > 0, inside / np.maximum(area, 1e-300), 0.0)
    return mean, frac


def _albedo_rows(
    rays: np.ndarray,
    T_cam_world: FloatArray,
    tex: TargetTexture,
    cam: Camera,
    env: np.ndarray,
    T_world_env: FloatArray | None = None,
) -> np.ndarray:
    """Albedo of the samples ``rays`` (m, n, 2): the target where its plane (z = 0 of the
    world) is hit, the background (fixed in the frame ``T_world_env``, default the world's)
    elsewhere."""
    s = cam.supersample
    T_cam_env = T_cam_world if T_world_env is None else T_cam_world @ T_world_env
    out = _background(rays[::s, ::s], T_cam_env, env)
    out = np.repeat(np.repeat(out, s, axis=0), s, axis=1)
    x = rays[..., 0].astype(np.float64)
    y = rays[..., 1].astype(np.float64)
    R = T_cam_world[:3, :3]
    t = T_cam_world[:3, 3]
    n = R[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = float(n @ t) / (n[0] * x + n[1] * y + n[2])
    hit = np.isfinite(lam) & (lam > 0)
    lam = np.where(hit, lam, 0.0)
    r0, r1 = R[:, 0], R[:, 1]
    X = lam * (r0[0] * x + r0[1] * y + r0[2]) - r0 @ t
    Y = lam * (r1[0] * x + r1[1] * y + r1[2]) - r1 @ t
    u, v = tex.uv(X, Y)
    # footprint of a sample: the bounding box of its square mapped by the local Jacobian
    du_r, du_c = np.gradient(u)
    dv_r, dv_c = np.gradient(v)
    wu = np.clip(np.abs(du_r) + np.abs(du_c), 1e-6, 50.0)
    wv = np.clip(np.abs(dv_r) + np.abs(dv_c), 1e-6, 50.0)
    h, w = tex.albedo.shape
    sel = hit & (u > -wu) & (u < w + wu) & (v > -wv) & (v < h + wv)
    if not np.any(sel):
        return out
    mean, frac = _box_mean(tex, u[sel], v[sel], wu[sel], wv[sel])
    out[sel] = frac * mean + (1.0 - frac) * out[sel]
    return out


def render_target_frame(
    cam: Camera,
    T_world_cam: FloatArray,
    tex: TargetTexture,
    env: np.ndarray,
    photometry: Any,
    rng: np.random.Generator,
    chunk_rows: int = 240,
    T_world_env: FloatArray | None = None,
) -> np.ndarray:
    """An 8-bit grey image ``(H, W)`` of the target (world = its frame) from ``T_world_cam``;
    the background ``env`` is fixed in the frame ``T_world_env`` (default the world's)."""
    T_cam_world = se3.invert_transforms(T_world_cam)
    s = cam.supersample
    w, h = cam.size
    rows = []
    step = max(s, (chunk_rows // s) * s)
    for r0 in range(0, h * s, step):
        alb = _albedo_rows(cam.rays[r0 : r0 + step], T_cam_world, tex, cam, env, T_world_env)
        rows.append(alb.reshape(alb.shape[0] // s, s, w, s).mean(axis=(1, 3)))
    return apply_photometry(np.concatenate(rows, axis=0), photometry, rng)


def project_corners(cam: Camera, T_world_cam: FloatArray, points: FloatArray) -> FloatArray:
    """True pixels ``(m, 2)`` of target points ``(m, 3)`` (world = target frame), NaN for
    points behind the camera or outside the image."""
    T_cw = se3.invert_transforms(T_world_cam)
    p = se3.transform_points(T_cw, points)
    front = p[:, 2] > 1e-6
    xn = p[:, :2] / np.where(front, p[:, 2], 1.0)[:, None]
    ok = front & (np.linalg.norm(xn, axis=1) < cam.r_max)
    xyz = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
    uv, _ = cv2.projectPoints(xyz, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    uv = uv.reshape(-1, 2)
    w, h = cam.size
    ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    uv[~ok] = np.nan
    return np.asarray(uv, dtype=float)


def board_proxy(target: AprilGrid | Charuco) -> tuple[Board, FloatArray]:
    """A checkerboard standing in for ``target`` where the articulated renderer
    (:func:`sample_data_gen.render.render_scenario`) places its cameras and judges views,
    and its frame in the target's.

    The proxy's inner corners cover the target's corners (a ChArUco's inner corners exactly,
    an AprilGrid's tag corners to within one tag pitch), centred on them; its frame has the
    checkerboard's orientation (y down the printed side, z into the board), so for Kalibr's
    AprilGrid frame (y up, z out of the target) it is turned half a turn about x.

    Parameters
    ----------
    target : AprilGrid or Charuco

    Returns
    -------
    board : Board
        Squares of the ChArUco's side or the AprilGrid's tag pitch (tag and gap).
    T_target_board : ndarray, shape (4, 4)
        Maps the proxy board's frame into the target's.
    """
    pts = target.points()
    if isinstance(target, Charuco):
        R, pitch = np.eye(3), target.square_length
    else:
        R, pitch = np.diag([1.0, -1.0, -1.0]), target.tag_size * (1.0 + target.spacing)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    extent = np.ptp((pts - centre) @ R, axis=0)
    cols, rows = (int(np.ceil(e / pitch - 1e-6)) + 1 for e in extent[:2])
    board = Board(cols, rows, float(pitch))
    return board, se3.transforms_from_rt(R, centre - R @ board.centre)


def classify_target_view(
    cam: Camera, target: AprilGrid | Charuco, T_world_cam: FloatArray
) -> tuple[str, int]:
    """``("full"|"partial"|"none", corners in view)`` of ``target`` (world = its frame):
    "full" when every corner is in the image, "none" when none is."""
    uv = project_corners(cam, T_world_cam, target.points())
    n_in = int(np.count_nonzero(np.all(np.isfinite(uv), axis=1)))
    if n_in == target.n_corners:
        return "full", n_in
    return ("partial" if n_in else "none"), n_in


def _look_at(P: FloatArray, target: FloatArray, up: FloatArray, roll_deg: float) -> FloatArray:
    z = target - P
    z = z / np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    roll = se3.matrix_from_rotvec(np.array([0.0, 0.0, np.radians(roll_deg)]))
    return np.stack([x, y, z], axis=1) @ roll


def _visible(cam: Camera, T_wc: FloatArray, pts: FloatArray, margin: float) -> np.ndarray:
    uv = project_corners(cam, T_wc, pts)
    w, h = cam.size
    return (
        np.all(np.isfinite(uv), axis=1)
        & (uv[:, 0] >= margin)
        & (uv[:, 0] <= w - 1 - margin)
        & (uv[:, 1] >= margin)
        & (uv[:, 1] <= h - 1 - margin)
    )


def _sample_poses(
    rng: np.random.Generator,
    cam: Camera,
    pts: FloatArray,
    outline: FloatArray,
    normal_sign: float,
    frames: int,
    max_tilt_deg: float = 45.0,
) -> tuple[FloatArray, list[str], FloatArray]:
    """``T_world_cam`` (n, 4, 4), each frame's kind ("full" or "partial") and visible
    fraction: frame 0 and every other frame show the whole target, the rest 30-70 %."""
    centre = 0.5 * (outline.min(axis=0) + outline.max(axis=0))
    extent = float(np.max(outline.max(axis=0) - outline.min(axis=0)))
    f = float(cam.K[0, 0])
    base = f * extent / (0.75 * cam.width)  # the target spans ~3/4 of the width head-on
    half_fov = 0.5 * cam.width / f
    kinds = ["full" if i % 2 == 0 else "partial" for i in range(frames)]
    T = np.zeros((frames, 4, 4))
    vis = np.zeros(frames)
    # image "down" along the target's y (ChArUco) or -y (AprilGrid, y up): an upright view
    up = np.array([0.0, -normal_sign, 0.0])
    for i, kind in enumerate(kinds):
        for _ in range(_MAX_TRIES):
            ang = rng.uniform(0, 2 * np.pi)
            axis = np.array([np.cos(ang), np.sin(ang), 0.0])
            tilt = rng.uniform(10.0, max_tilt_deg)
            d = se3.matrix_from_rotvec(axis * np.radians(tilt)) @ np.array([0, 0, normal_sign])
            dist = base * rng.uniform(0.9, 1.4)
            P = centre + dist * d
            a2 = rng.uniform(0, 2 * np.pi)
            direc = np.array([np.cos(a2), np.sin(a2), 0.0])
            off = (0.05 if kind == "full" else rng.uniform(0.4, 1.1)) * dist * half_fov
            R = _look_at(P, centre + off * direc, up, rng.uniform(-30, 30))
            Twc = se3.transforms_from_rt(R, P)
            if kind == "full":
                if not np.all(_visible(cam, Twc, outline, 6.0)):
                    continue
                frac = 1.0
            else:
                frac = float(np.mean(_visible(cam, Twc, pts, 0.0)))
                if not 0.3 <= frac <= 0.7:
                    continue
            T[i], vis[i] = Twc, frac
            break
        else:  # pragma: no cover - the sampler's ranges always find views
            raise RuntimeError(f"could not place frame {i} ({kind}); try another seed")
    return T, kinds, vis


def default_target(kind: str) -> AprilGrid | Charuco:
    """The target a rendered sequence shows: a 6x6 AprilGrid (tags of 0.088 m, spacing 0.3,
    Kalibr's sample) or an 11x8 ChArUco of 0.03 m squares, 0.022 m DICT_5X5_100 markers."""
    if kind == "aprilgrid":
        return AprilGrid(6, 6, 0.088, 0.3)
    if kind == "charuco":
        return Charuco(11, 8, 0.03, 0.022, "DICT_5X5_100")
    raise ValueError(f"unknown target kind {kind!r}; choose one of {', '.join(TARGET_KINDS)}")


def render_target_sequence(
    out_dir: str | Path,
    target: AprilGrid | Charuco,
    *,
    seed: int = 0,
    frames: int = 30,
    size: tuple[int, int] = (640, 480),
    blur: bool = True,
    noise_sigma: float = 2.0,
    supersample: int = 2,
) -> Path:
    """Render a camera filming ``target`` into ``out_dir`` (see the module documentation).

    Parameters
    ----------
    out_dir : str or Path
        Folder to write (``images/``, ``target.yaml``, ``truth.yaml``,
        ``truth_corners.npz``).
    target : AprilGrid or Charuco
    seed : int
        Fixes the camera, the motion, lighting and noise.
    frames : int
        Images (at least 1); odd frames show 30-70 % of the target.
    size : (width, height)
        Image size, pixels.
    blur : bool
        Random Gaussian blur (sigma 0.3-1.0 px) per image.
    noise_sigma : float
        Gaussian sensor noise, grey levels.
    supersample : int
        Samples per pixel along each axis (on top of the exact box filter).

    Returns
    -------
    Path
        ``out_dir``.
    """
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    w, h = (int(v) for v in size)
    if w < 64 or h < 64:
        raise ValueError(f"image size {w}x{h} is too small")
    t0 = time.perf_counter()
    out = Path(out_dir)
    cam = make_camera(np.random.default_rng([seed, 60, 0]), (w, h), supersample)
    tex = target_texture(target)
    pts = target.points()
    th, tw = tex.albedo.shape
    # the printed area's outline, in the target frame
    corners_uv = np.array([[0.0, 0.0], [tw, 0.0], [tw, th], [0.0, th]])
    ox = tex.x0 + corners_uv[:, 0] * tex.texel
    oy = (
        (tex.y0 + corners_uv[:, 1] * tex.texel)
        if tex.y_down
        else (tex.y0 - corners_uv[:, 1] * tex.texel)
    )
    outline = np.stack([ox, oy, np.zeros(4)], axis=1)
    # the camera looks at the printed side: -z for z into the board, +z for Kalibr's frame
    normal_sign = -1.0 if tex.y_down else 1.0
    rng = np.random.default_rng([seed, 61])
    T_wc, kinds, vis = _sample_poses(rng, cam, pts, outline, normal_sign, frames)
    env = _environment(np.random.default_rng([seed, 62]))
    img_rng = np.random.default_rng([seed, 63])
    truth = np.full((frames, pts.shape[0], 2), np.nan)
    blur_sigma: list[float] = []
    for i in range(frames):
        ph = _random_photometry(img_rng, blur, noise_sigma)
        img = render_target_frame(cam, T_wc[i], tex, env, ph, img_rng)
        ok, buf = cv2.imencode(".png", img)
        if not ok:  # pragma: no cover - cv2 failure
            raise RuntimeError("PNG encoding failed")
        atomic_write_bytes(out / "images" / f"img_{i:05d}.png", buf.tobytes())
        truth[i] = project_corners(cam, T_wc[i], pts)
        blur_sigma.append(ph.blur_sigma)
    write_target_yaml(out / "target.yaml", target)
    with atomic_path(out / "truth_corners.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, corners=truth, board_points=pts)
    header = make_header(
        TRUTH_KIND,
        inputs={},
        method=(
            f"rendered {target.kind} sequence (sample_data_gen.target_render): seed {seed}, "
            f"{frames} frames, {w}x{h}, target {target.short()}"
        ),
        units={"length": "metres", "intensity": "grey levels (0-255)", "K": "px"},
        frames={
            "T_world_cam": "the camera in the target's frame",
            "target": "see acs_cli.core.targets (Kalibr's frame for aprilgrid, OpenCV's "
            "for charuco)",
        },
    )
    body = {
        "target": target_to_mapping(target),
        "target_short": target.short(),
        "seed": int(seed),
        "n_frames": int(frames),
        "camera": {
            "model": "pinhole",
            "image_size": [w, h],
            "camera_matrix": cam.K,
            "distortion": cam.dist,
            "distortion_names": ["k1", "k2", "p1", "p2", "k3"],
        },
        "images": "images/img_{index:05d}.png",
        "truth_corners": "truth_corners.npz (corners (n, m, 2) px, NaN outside the image; "
        "board_points (m, 3) m)",
        "visibility": kinds,
        "visible_fraction": [round(float(v), 4) for v in vis],
        "T_world_cam": T_wc,
        "blur_sigma_px": blur_sigma,
        "render": {
            "supersample": supersample,
            "anti_aliasing": "exact box filter of each sample's footprint (integral image)",
            "noise_sigma": float(noise_sigma),
            "seconds_total": round(time.perf_counter() - t0, 2),
        },
    }
    write_yaml_artifact(out / "truth.yaml", header, body)
    return out
