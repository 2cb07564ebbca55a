"""Rendered markerless sequences: a two-camera ACS moving through a textured room.

No calibration board: both cameras of an articulated rig film the inside of a box room
whose six faces (four walls, floor, ceiling) carry natural-looking, feature-rich textures,
so that structure-from-motion reconstructs each camera's trajectory up to scale.

Room frame (``world``, the frame of every ``T_world_cam`` written here): origin at a floor
corner, x along the room's length, y along its width, z up; the room is
``[0, L] x [0, W] x [0, H]`` metres. Each face has its own texture (albedo times a
Lambertian shading from a lamp under the ceiling, baked in: the scene's radiance is
view-independent), sampled at ``texel`` metres. Textures are multi-octave noise, blobs,
strokes and speckles under a slowly varying contrast, drawn once from the seed: nothing
repeats.

Rendering casts the ray of each of ``supersample x supersample`` samples per pixel (pinhole,
no distortion) from the camera centre to the face it leaves the box through, samples that
face's texture bilinearly (one ``cv2.remap`` over an atlas of the six textures), averages
the samples of each pixel, adds Gaussian sensor noise and quantises to 8 bits.

Motion (see :class:`MarkerlessMotion`): camera A is on the reference body, which moves
smoothly through the room (sums of sinusoids in position and in a rotation vector);
camera B is on a second body joined to it by a ball joint at ``o_a`` (A's frame) and ``o_b``
(B's frame), articulated smoothly about all three axes (:class:`SyntheticRig`'s model:
``T_a_b = [Q R0, o_a - Q R0 o_b]``). Everything is a smooth function of the rig's time.

Clocks: camera A's image ``i`` shows the rig at time ``t_i = i / fps`` and is stamped
``t_i``. Camera B's clock runs ``time_offset_s`` ahead of A's (acscal's convention,
:mod:`acs_cli.core.time_offset`: B's clock minus A's): its image ``i`` is stamped ``t_i``
too, but shows the rig at time ``t_i - time_offset_s``, so A's image stamped ``t`` pairs
with B's at B's time ``t + time_offset_s``.

Output: ``OUT/markerless/cam_a/img_00000.png``, ..., ``OUT/markerless/cam_b/...``,
``OUT/markerless/truth.yaml`` (kind ``render_truth``, the layout of
:func:`sample_data_gen.render.render_scenario`'s) and the true trajectories
``truth_a.tum``, ``truth_b.tum`` (``T_world_cam`` in the room frame, metres, stamped with
each camera's own clock).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from acs_cli.core import se3
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.atomic import atomic_write_bytes
from acs_cli.io.trajectory import write_tum
from sample_data_gen.acs_sim import SyntheticRig
from sample_data_gen.render import TRUTH_KIND, _encode_png, _rot, _sample_grid

__all__ = [
    "FACES",
    "ROOM_SIZE",
    "MarkerlessMotion",
    "Room",
    "make_room",
    "markerless_motion",
    "pinhole_rays",
    "render_markerless",
    "render_room_view",
    "room_clearance",
]

FloatArray = se3.FloatArray

#: Default room: length (x), width (y), height (z), metres.
ROOM_SIZE = (8.0, 6.0, 3.0)
#: Faces in atlas order: face ``2k`` is the plane ``axis k = 0``, ``2k + 1`` the far one.
FACES = ("wall_x0", "wall_x1", "wall_y0", "wall_y1", "floor", "ceiling")
SCENARIO = "markerless"
#: In-plane axes (texture columns, rows) of the faces normal to x, y and z.
_FACE_AXES = ((1, 2), (0, 2), (0, 1))
_MAX_TRIES = 200
_REMAP_LIMIT = 32000  # cv2.remap's source images must stay below SHRT_MAX texels a side
_MAX_TEXELS = 50_000_000  # 200 MB of float32 atlas, about 1 GB while drawing


# --------------------------------------------------------------------------- the room


def room_clearance(size: FloatArray, points: FloatArray) -> FloatArray:
    """Distance (metres) from points ``(n, 3)`` (room frame) to the nearest face of the room
    ``[0, size[0]] x [0, size[1]] x [0, size[2]]``, ``(n,)``; negative outside."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    return np.asarray(np.minimum(p, np.asarray(size, dtype=float) - p).min(axis=1))


@dataclass(frozen=True)
class Room:
    """A textured box room.

    Attributes
    ----------
    size : ndarray, shape (3,)
        Length, width, height (metres): the room is ``[0, size[0]] x [0, size[1]] x
        [0, size[2]]`` in the room frame.
    texel : float
        Texture sampling step on every face, metres.
    atlas : ndarray, shape (rows, cols), float32
        The six face textures (radiance in [0, 1]) stacked vertically, each with a one-texel
        replicated border; face ``f``'s texel ``(r, c)`` is at ``atlas[row0[f] + r, 1 + c]``.
    row0 : ndarray, shape (6,), float32
        First row of each face's texture in ``atlas`` (in :data:`FACES` order).
    lamp : ndarray, shape (3,)
        The lamp's position in the room frame (metres), for the record.
    """

    size: FloatArray
    texel: float
    atlas: np.ndarray
    row0: np.ndarray
    lamp: FloatArray

    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance (metres) from points ``(n, 3)`` (room frame) to the nearest face, ``(n,)``;
        negative outside the room."""
        return room_clearance(self.size, points)


def _fbm(rng: np.random.Generator, shape: tuple[int, int], texel: float, hurst: float) -> Any:
    """Zero-mean, unit-std multi-octave value noise ``shape`` (rows, cols), float32: octaves
    from 2 m down to 2 texels, amplitude ``cell ** hurst``. Not periodic (no tiling)."""
    rows, cols = shape
    out = np.zeros(shape, np.float32)
    cell = 2.0
    while cell >= 2.0 * texel:
        n_r = max(2, math.ceil(rows * texel / cell) + 2)
        n_c = max(2, math.ceil(cols * texel / cell) + 2)
        small = rng.normal(size=(n_r, n_c)).astype(np.float32)
        out += np.float32(cell**hurst) * cv2.resize(
            small, (cols, rows), interpolation=cv2.INTER_CUBIC
        )
        cell *= 0.5
    out -= out.mean()
    return out / max(float(out.std()), 1e-6)


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], texel: float) -> Any:
    """Zero-mean, unit-std noise ``shape`` (rows, cols), float32, with octaves from 2 m down
    to 10 cm: :func:`_fbm` on a 5 cm grid, resized to ``shape``."""
    step = max(texel, 0.05)
    rows, cols = shape
    coarse = (max(2, math.ceil(rows * texel / step)), max(2, math.ceil(cols * texel / step)))
    return cv2.resize(_fbm(rng, coarse, step, 1.0), (cols, rows), interpolation=cv2.INTER_LINEAR)


def _draw_shapes(rng: np.random.Generator, tex: np.ndarray, texel: float) -> None:
    """Draw blobs (filled and outlined ellipses, 0.8-15 cm) and strokes (random-walk
    polylines) into ``tex`` (rows, cols) in place, at densities drawn per face (per square
    metre)."""
    rows, cols = tex.shape
    area = rows * cols * texel * texel
    n = int(area * rng.uniform(60.0, 160.0))
    cx = rng.integers(0, cols, n)
    cy = rng.integers(0, rows, n)
    major = np.exp(rng.uniform(np.log(0.008), np.log(0.15), n)) / texel
    minor = np.maximum(1, (major * rng.uniform(0.25, 1.0, n)).astype(int))
    major = np.maximum(1, major.astype(int))
    thick = np.where(rng.uniform(size=n) < 0.7, -1, rng.integers(1, 5, n))
    val = rng.uniform(0.05, 0.95, n)
    angle = rng.uniform(0.0, 180.0, n)
    for i in range(n):
        cv2.ellipse(
            tex,
            (int(cx[i]), int(cy[i])),
            (int(major[i]), int(minor[i])),
            float(angle[i]),
            0,
            360,
            float(val[i]),
            int(thick[i]),
        )
    n = int(area * rng.uniform(10.0, 40.0))
    n_pts = rng.integers(4, 14, n)
    heading = rng.uniform(0, 2 * np.pi, (n, 1)) + np.cumsum(rng.normal(0, 0.6, (n, 14)), 1)
    step = rng.uniform(0.01, 0.06, (n, 1)) / texel
    start = np.stack([rng.uniform(0, cols, n), rng.uniform(0, rows, n)], 1)[:, None, :]
    walk = np.stack([np.cos(heading), np.sin(heading)], 2) * step[:, :, None]
    pts = np.rint(start + np.cumsum(walk, 1)).astype(np.int32)  # (n, 14, 2)
    dark = rng.uniform(size=n) < 0.6
    val = np.where(dark, rng.uniform(0.03, 0.3, n), rng.uniform(0.7, 0.97, n))
    width = rng.integers(1, 6, n)
    for i in range(n):
        cv2.polylines(tex, [pts[i, : n_pts[i]]], False, float(val[i]), int(width[i]))


def _face_texture(rng: np.random.Generator, shape: tuple[int, int], texel: float) -> Any:
    """One face's albedo ``shape`` (rows, cols), float32 in [0.03, 0.97].

    A base tone with multi-octave noise, blobs and strokes blended in under a smooth
    opacity (so their contrast varies over the face), speckles, and a slight blur (0.6
    texel) against aliasing. Every style parameter is drawn per face.
    """
    base = rng.uniform(0.3, 0.6)
    tex = base + rng.uniform(0.12, 0.2) * _fbm(rng, shape, texel, rng.uniform(0.3, 0.8))
    contrast = np.exp(0.35 * _smooth_noise(rng, shape, texel))
    tex = (base + (tex - base) * contrast).astype(np.float32)
    shapes = tex.copy()
    _draw_shapes(rng, shapes, texel)
    alpha = np.clip(0.65 + 0.3 * _smooth_noise(rng, shape, texel), 0.15, 1.0)
    tex += alpha * (shapes - tex)
    rows, cols = shape
    n_speck = int(rows * cols * texel * texel * rng.uniform(300.0, 1500.0))
    r = rng.integers(0, rows, n_speck)
    c = rng.integers(0, cols, n_speck)
    tex[r, c] = rng.uniform(0.0, 1.0, n_speck).astype(np.float32)
    tex = cv2.GaussianBlur(tex, (0, 0), 0.6)
    return np.clip(tex, 0.03, 0.97)


def _shading(size: FloatArray, face: int, shape: tuple[int, int], texel: float, lamp: Any) -> Any:
    """Lambertian irradiance (relative, float32 ``shape``) of a face's texels from a point
    lamp at ``lamp`` (room frame) plus an ambient term."""
    k = face // 2
    ax_c, ax_r = _FACE_AXES[k]
    rows, cols = shape
    dc = float(lamp[ax_c]) - (np.arange(cols, dtype=np.float32) + 0.5) * np.float32(texel)
    dr = float(lamp[ax_r]) - (np.arange(rows, dtype=np.float32) + 0.5) * np.float32(texel)
    dk = float(lamp[k] - (0.0 if face % 2 == 0 else size[k]))
    r2 = (dr * dr)[:, None] + (dc * dc)[None, :] + np.float32(dk * dk)
    cos = np.float32(abs(dk)) / np.sqrt(r2)
    return (0.55 + 1.6 * cos / (1.0 + r2 / 4.0)).astype(np.float32)


def make_room(
    seed: int, size: tuple[float, float, float] = ROOM_SIZE, texel: float = 0.004
) -> Room:
    """The textured room of ``seed``.

    Parameters
    ----------
    seed : int
        Fixes every texture (face ``f`` draws from ``default_rng([seed, 60, f])``).
    size : (float, float, float)
        Length (x), width (y) and height (z) of the room, metres.
    texel : float
        Texture sampling step, metres (4 mm: about one texel per pixel at 3 m for a
        640-pixel-wide image).

    Returns
    -------
    Room

    Raises
    ------
    ValueError
        If a dimension is not positive, or the atlas would exceed ``cv2.remap``'s limit of
        32000 texels a side or 5e7 texels in all (a texel too small for the room).
    """
    dims = np.asarray(size, dtype=float)
    if dims.shape != (3,) or not np.all(dims > 0) or not texel > 0:
        raise ValueError(f"room size {size} and texel {texel} must be positive")
    lamp = np.array([0.5 * dims[0], 0.5 * dims[1], max(0.5 * dims[2], dims[2] - 0.4)])
    shapes = []
    for face in range(len(FACES)):
        ax_c, ax_r = _FACE_AXES[face // 2]
        shapes.append((math.ceil(dims[ax_r] / texel), math.ceil(dims[ax_c] / texel)))
    row = sum(r + 2 for r, _ in shapes)  # one texel of border above and below each face
    width = max(c for _, c in shapes) + 2
    if row > _REMAP_LIMIT or width > _REMAP_LIMIT or row * width > _MAX_TEXELS:
        raise ValueError(
            f"a {texel} m texel makes a {width}x{row} texture atlas, more than cv2.remap "
            f"takes ({_REMAP_LIMIT} a side) or than {_MAX_TEXELS:.0e} texels (memory); use a "
            "larger texel or a smaller room"
        )
    atlas = np.zeros((row, width), np.float32)
    row0 = np.zeros(len(FACES), np.float32)
    r = 0
    for face, shape in enumerate(shapes):
        tex = _face_texture(np.random.default_rng([seed, 60, face]), shape, texel)
        tex *= _shading(dims, face, shape, texel, lamp)
        tile = cv2.copyMakeBorder(tex, 1, 1, 1, 1, cv2.BORDER_REPLICATE)
        atlas[r : r + tile.shape[0], : tile.shape[1]] = tile
        row0[face] = r + 1
        r += tile.shape[0]
    np.clip(atlas, 0.0, 1.0, out=atlas)
    return Room(size=dims, texel=float(texel), atlas=atlas, row0=row0, lamp=lamp)


# --------------------------------------------------------------------------- rendering


def pinhole_rays(K: FloatArray, size: tuple[int, int], supersample: int) -> Any:
    """Normalised coordinates ``(2, H*s, W*s)``, float32, of the ``s x s`` samples of every
    pixel of a pinhole camera ``K`` (pixel centres at integers, as in OpenCV): the ray of a
    sample is ``(x, y, 1)`` in the camera frame."""
    gx, gy = _sample_grid(size, supersample)
    y = (gy - K[1, 2]) / K[1, 1]
    x = (gx - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return np.stack([x, y]).astype(np.float32)


def _radiance(room: Room, rays: np.ndarray, T_world_cam: FloatArray) -> tuple[Any, Any]:
    """Radiance and depth (metres along the optical axis) of every sample of ``rays``
    ``(2, m, n)`` seen from ``T_world_cam`` (room frame, camera inside the room)."""
    R = np.asarray(T_world_cam[:3, :3], np.float32)
    p = np.asarray(T_world_cam[:3, 3], np.float32)
    x, y = rays
    d = [R[k, 0] * x + R[k, 1] * y + R[k, 2] for k in range(3)]  # directions, room frame
    t_exit = []
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):
            inv = np.float32(1.0) / d[k]
            # from inside the box, the exit through this pair of planes is the larger root
            t_exit.append(np.maximum((0.0 - p[k]) * inv, (np.float32(room.size[k]) - p[k]) * inv))
    depth = np.minimum(np.minimum(t_exit[0], t_exit[1]), t_exit[2])
    on_x = t_exit[0] == depth
    on_z = (t_exit[2] == depth) & ~on_x
    hit = [p[k] + depth * d[k] for k in range(3)]
    u = np.where(on_x, hit[1], hit[0])  # texture column axis: y on x-faces, else x
    v = np.where(on_z, hit[1], hit[2])  # texture row axis: y on the floor and ceiling, else z
    face = np.where(on_x, 0, np.where(on_z, 4, 2)) + (
        np.where(on_x, d[0], np.where(on_z, d[2], d[1])) > 0
    )
    inv_texel = np.float32(1.0 / room.texel)
    map_x = u * inv_texel + np.float32(0.5)  # + 1 (border) - 0.5 (texel centres)
    map_y = v * inv_texel - np.float32(0.5) + room.row0[face]
    rad = cv2.remap(room.atlas, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return rad, depth


def render_room_view(
    room: Room,
    rays: np.ndarray,
    T_world_cam: FloatArray,
    *,
    supersample: int,
    noise_sigma: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, tuple[float, float]]:
    """One 8-bit grey image of the room and the range of depths it shows.

    Parameters
    ----------
    room : Room
    rays : ndarray, shape (2, H*s, W*s), float32
        From :func:`pinhole_rays` with ``supersample = s``.
    T_world_cam : ndarray, shape (4, 4)
        The camera in the room frame (metres); its centre must be inside the room.
    supersample : int
        Samples per pixel along each axis (``s``); they are averaged per pixel.
    noise_sigma : float
        Gaussian sensor noise, grey levels.
    rng : numpy.random.Generator
        Draws the noise.

    Returns
    -------
    image : ndarray, shape (H, W), uint8
    depth_range : (float, float)
        Smallest and largest depth (metres along the optical axis) of a sample.
    """
    rad, depth = _radiance(room, rays, T_world_cam)
    s = supersample
    h, w = rad.shape[0] // s, rad.shape[1] // s
    if s > 1:
        rad = cv2.resize(rad, (w, h), interpolation=cv2.INTER_AREA)
    img = 255.0 * rad.astype(np.float64)
    if noise_sigma > 0:
        img += rng.normal(scale=noise_sigma, size=img.shape)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return out, (float(depth.min()), float(depth.max()))


# --------------------------------------------------------------------------- motion


@dataclass(frozen=True)
class _Waves:
    """Three smooth signals: ``x_c(t) = sum_j amp[j, c] sin(omega[j, c] t + phase[j, c])``."""

    amp: FloatArray  # (m, 3)
    omega: FloatArray  # (m, 3), rad/s
    phase: FloatArray  # (m, 3), rad

    def __call__(self, t: FloatArray) -> FloatArray:
        arg = np.asarray(t, dtype=float)[:, None, None] * self.omega + self.phase
        return np.asarray(np.sum(self.amp * np.sin(arg), axis=1))

    def scaled(self, factor: float) -> _Waves:
        return _Waves(self.amp * factor, self.omega, self.phase)


def _waves(
    rng: np.random.Generator,
    amplitude: FloatArray,
    cycles: tuple[float, float],
    duration: float,
    terms: int = 2,
) -> _Waves:
    """``terms`` sinusoids per component, ``cycles`` (low, high) per ``duration`` seconds,
    their amplitudes summing to ``amplitude`` ``(3,)`` per component."""
    weights = rng.uniform(0.3, 1.0, size=(terms, 3))
    amp = np.asarray(amplitude, dtype=float) * weights / weights.sum(axis=0)
    omega = 2.0 * np.pi * rng.uniform(*cycles, size=(terms, 3)) / duration
    return _Waves(amp, omega, rng.uniform(0.0, 2.0 * np.pi, size=(terms, 3)))


@dataclass(frozen=True)
class MarkerlessMotion:
    """The rig's motion as smooth (infinitely differentiable) functions of the rig's time.

    ``T_world_a(t) = [R_base Exp(w(t)), centre + x(t)]`` (room frame, metres; ``w`` a
    rotation vector in A's frame, radians) and ``T_a_b(t) = rig.T_a_b(Exp(q(t)))`` (the
    articulation ``q`` a rotation vector in A's frame), with ``x``, ``w``, ``q`` sums of
    sinusoids.

    Attributes
    ----------
    rig : SyntheticRig
        The joint (``o_a``, ``o_b``, metres) and the rest rotation ``R0 = R_a_b``.
    R_base : ndarray, shape (3, 3)
        Camera A's mean orientation ``R_world_a``.
    centre : ndarray, shape (3,)
        Camera A's mean position, room frame, metres.
    translation, rotation, articulation : _Waves
        ``x(t)`` (metres), ``w(t)`` and ``q(t)`` (radians).
    """

    rig: SyntheticRig
    R_base: FloatArray
    centre: FloatArray
    translation: _Waves
    rotation: _Waves
    articulation: _Waves

    def T_world_a(self, t: FloatArray) -> FloatArray:
        """Camera A's poses ``(n, 4, 4)`` (room frame) at rig times ``t`` ``(n,)`` (s)."""
        R = self.R_base @ se3.matrix_from_rotvec(self.rotation(t).reshape(-1, 3))
        return se3.transforms_from_rt(R, self.centre + self.translation(t))

    def T_a_b(self, t: FloatArray) -> FloatArray:
        """Relative poses ``T_a_b`` ``(n, 4, 4)`` at rig times ``t`` ``(n,)`` (s)."""
        return self.rig.T_a_b(se3.matrix_from_rotvec(self.articulation(t).reshape(-1, 3)))

    def T_world_b(self, t: FloatArray) -> FloatArray:
        """Camera B's poses ``(n, 4, 4)`` (room frame) at rig times ``t`` ``(n,)`` (s)."""
        return self.T_world_a(t) @ self.T_a_b(t)


def _look(forward: FloatArray) -> FloatArray:
    """``R_world_cam`` of a camera looking along ``forward`` (room frame) with its y axis
    (image down) as close to ``-z`` (down) as it can be."""
    f = forward / np.linalg.norm(forward)
    x = np.cross(f, np.array([0.0, 0.0, 1.0]))
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(f, x), f], axis=1)


def _draw_rig(rng: np.random.Generator) -> SyntheticRig:
    """A ball joint 0.25-0.45 m from each camera; B looks 100-150 deg to A's side, pitched
    by up to 20 deg; the cameras at least 0.25 m apart."""
    while True:
        sgn = 1.0 if rng.uniform() < 0.5 else -1.0
        R0 = _rot(np.array([0.0, 1.0, 0.0]), sgn * rng.uniform(100.0, 150.0)) @ _rot(
            np.array([1.0, 0.0, 0.0]), rng.uniform(-20.0, 20.0)
        )
        da = np.array([sgn * rng.uniform(0.5, 1.0), rng.uniform(-0.3, 0.3), rng.uniform(-0.6, 0)])
        db = np.array([-sgn * rng.uniform(0.5, 1.0), rng.uniform(-0.3, 0.3), rng.uniform(-0.6, 0)])
        o_a = rng.uniform(0.25, 0.45) * da / np.linalg.norm(da)
        o_b = rng.uniform(0.25, 0.45) * db / np.linalg.norm(db)
        if np.linalg.norm(o_a - R0 @ o_b) > 0.25:  # B's centre in A's frame, at rest
            return SyntheticRig(o_a=o_a, o_b=o_b, R0=R0)


def markerless_motion(
    seed: int,
    room_size: FloatArray,
    duration: float,
    *,
    time_span: tuple[float, float] | None = None,
    margin: float = 0.5,
) -> MarkerlessMotion:
    """Draw the rig and its smooth motion through the room for ``seed``.

    Camera A's path spans 1.2-1.8 m (bounding-box diagonal over ``[0, duration]``) about a
    point near the room's centre at 43-53% of its height; its orientation swings 15-30 deg
    about its x and y axes and 15-20 deg about its optical axis, looking 5-15 deg below the
    horizon on average; the joint articulates by 20-35 deg about each axis. Frequencies
    are 0.3-1.2 cycles per ``duration``, so the motion fills the recording whatever its
    length.

    Parameters
    ----------
    seed : int
        Draws from ``default_rng([seed, 70])``.
    room_size : ndarray, shape (3,)
        The room (metres), as :attr:`Room.size`.
    duration : float
        Length of the recording, seconds (``frames / fps``).
    time_span : (float, float), optional
        Rig times (s) over which both cameras must keep ``margin`` from every face; default
        ``[-duration, 2 duration]``, so that one motion serves every time offset up to
        ``duration`` either way.
    margin : float
        Smallest distance of either camera centre from a face, metres.

    Returns
    -------
    MarkerlessMotion

    Raises
    ------
    RuntimeError
        If no motion of the kind fits the room in 200 draws (a room too small).
    """
    rng = np.random.default_rng([seed, 70])
    size = np.asarray(room_size, dtype=float)
    lo, hi = time_span if time_span is not None else (-duration, 2.0 * duration)
    t_check = np.linspace(lo, hi, max(400, int(50 * (hi - lo) / max(duration, 1e-9))))
    t_seq = np.linspace(0.0, duration, 200)
    for _ in range(_MAX_TRIES):
        rig = _draw_rig(rng)
        az = rng.uniform(0.0, 2.0 * np.pi)
        el = np.radians(rng.uniform(5.0, 15.0))
        R_base = _look(np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), -np.sin(el)]))
        centre = np.array(
            [
                0.5 * size[0] + rng.uniform(-0.3, 0.3),
                0.5 * size[1] + rng.uniform(-0.3, 0.3),
                size[2] * rng.uniform(0.43, 0.53),
            ]
        )
        trans = _waves(rng, np.array([1.0, 0.8, 0.25]), (0.3, 0.8), duration)
        x = trans(t_seq)
        diag = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
        trans = trans.scaled(rng.uniform(1.2, 1.8) / max(diag, 1e-9))
        rot_amp = np.radians([rng.uniform(15, 30), rng.uniform(15, 30), rng.uniform(15, 20)])
        art_amp = np.radians(rng.uniform(20.0, 35.0, size=3))
        motion = MarkerlessMotion(
            rig=rig,
            R_base=R_base,
            centre=centre,
            translation=trans,
            rotation=_waves(rng, rot_amp, (0.4, 1.0), duration),
            articulation=_waves(rng, art_amp, (0.5, 1.2), duration),
        )
        T_a = motion.T_world_a(t_check)
        T_b = T_a @ motion.T_a_b(t_check)
        clear = min(
            float(np.min(room_clearance(size, T_a[:, :3, 3]))),
            float(np.min(room_clearance(size, T_b[:, :3, 3]))),
        )
        if clear >= margin:
            return motion
    raise RuntimeError(
        f"no rig motion keeps both cameras {margin} m inside a room of {size.tolist()} m; "
        "use a larger room"
    )


# --------------------------------------------------------------------------- writing


def _intrinsics(rng: np.random.Generator, size: tuple[int, int]) -> FloatArray:
    """A pinhole ``K`` ``(3, 3)``: focal 0.8-0.9 x width (a 58-64 deg horizontal field of
    view), square pixels, principal point within 1% of the image's width of the centre."""
    w, h = size
    f = w * rng.uniform(0.8, 0.9)
    cx = (w - 1) / 2 + rng.uniform(-0.01, 0.01) * w
    cy = (h - 1) / 2 + rng.uniform(-0.01, 0.01) * w
    return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])


def _motion_summary(
    motion: MarkerlessMotion, t_a: FloatArray, t_b: FloatArray, room: Room
) -> dict[str, Any]:
    """Ranges of the motion the images show (metres, degrees)."""
    T_a = motion.T_world_a(t_a)
    T_b = motion.T_world_b(t_b)
    p_a = T_a[:, :3, 3]
    R_a0_a = np.einsum("ji,njk->nik", T_a[0, :3, :3], T_a[:, :3, :3])
    R_b0_b = np.einsum("ji,njk->nik", T_b[0, :3, :3], T_b[:, :3, :3])
    T_a_b = motion.T_a_b(t_a)
    Q = T_a_b[:, :3, :3] @ motion.rig.R0.T
    axes = np.degrees(np.arccos(np.clip(T_a_b[:, 2, 2], -1.0, 1.0)))  # z_a . (R_a_b z_b)
    return {
        "path_extent_a_m": float(np.linalg.norm(p_a.max(axis=0) - p_a.min(axis=0))),
        "path_length_a_m": float(np.sum(np.linalg.norm(np.diff(p_a, axis=0), axis=1))),
        "max_rotation_from_first_deg": {
            "cam_a": float(np.max(se3.rotation_angle_deg(R_a0_a))),
            "cam_b": float(np.max(se3.rotation_angle_deg(R_b0_b))),
        },
        "max_articulation_deg": float(np.max(se3.rotation_angle_deg(Q))),
        "optical_axes_angle_deg": [float(axes.min()), float(axes.max())],
        "min_clearance_m": {
            "cam_a": float(np.min(room.clearance(p_a))),
            "cam_b": float(np.min(room.clearance(T_b[:, :3, 3]))),
        },
        "model": "T_world_a(t) = [R_base Exp(w(t)), centre + x(t)], T_a_b(t) = "
        "[Q(t) R0, o_a - Q(t) R0 o_b], Q(t) = Exp(q(t)); x, w, q sums of two sinusoids per "
        "component",
        "R_base": motion.R_base,
        "centre": motion.centre,
    }


def render_markerless(
    out_dir: str | Path,
    *,
    seed: int = 0,
    frames: int = 60,
    size: tuple[int, int] = (640, 480),
    fps: float = 30.0,
    time_offset_s: float = 0.0,
    room_size: tuple[float, float, float] = ROOM_SIZE,
    texel: float = 0.004,
    noise_sigma: float = 1.5,
    supersample: int = 2,
) -> Path:
    """Render the markerless sample into ``out_dir / "markerless"`` and return that folder.

    Parameters
    ----------
    out_dir : str or Path
        Parent folder; ``markerless/cam_a``, ``markerless/cam_b``, ``markerless/truth.yaml``,
        ``markerless/truth_a.tum`` and ``markerless/truth_b.tum`` are written under it.
    seed : int
        Fixes the room's textures, the cameras, the rig, its motion and the noise.
    frames : int
        Images per camera.
    size : (width, height)
        Image size in pixels.
    fps : float
        Frame rate (Hz); image ``i`` is stamped ``i / fps`` seconds.
    time_offset_s : float
        Camera B's clock minus camera A's: B's image ``i`` shows the rig at time
        ``i / fps - time_offset_s`` although it is stamped ``i / fps`` (see the module
        documentation); 0 for synchronised cameras.
    room_size : (float, float, float)
        Length, width and height of the room, metres.
    texel : float
        Texture sampling step, metres.
    noise_sigma : float
        Gaussian sensor noise, grey levels.
    supersample : int
        Samples per pixel along each axis.

    Returns
    -------
    Path
        ``out_dir / "markerless"``.

    Raises
    ------
    ValueError
        For fewer than 1 frame, an image smaller than 16x16, a non-positive ``fps``, a
        negative noise or a supersampling below 1, or a room or texel :func:`make_room`
        refuses.
    """
    w, h = (int(v) for v in size)
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    if w < 16 or h < 16:
        raise ValueError(f"image size {w}x{h} is too small")
    if not (fps > 0 and np.isfinite(time_offset_s)):
        raise ValueError("fps must be positive and time_offset_s finite")
    if noise_sigma < 0 or supersample < 1:
        raise ValueError("noise_sigma must be >= 0 and supersample >= 1")
    t0 = time.perf_counter()
    room = make_room(seed, room_size, texel)
    t_room = time.perf_counter() - t0
    duration = frames / fps
    stamps = np.arange(frames) / fps
    # one motion per seed for offsets up to the duration; larger ones widen the check
    span = (min(-duration, -time_offset_s), max(2.0 * duration, duration - time_offset_s))
    motion = markerless_motion(seed, room.size, duration, time_span=span)
    Ks = (
        _intrinsics(np.random.default_rng([seed, 10, 0]), (w, h)),
        _intrinsics(np.random.default_rng([seed, 10, 1]), (w, h)),
    )
    rig_times = (stamps, stamps - time_offset_s)
    poses = (motion.T_world_a(rig_times[0]), motion.T_world_b(rig_times[1]))
    out = Path(out_dir) / SCENARIO
    depth: dict[str, list[list[float]]] = {"cam_a": [], "cam_b": []}
    t_render = 0.0
    for c, name in enumerate(("cam_a", "cam_b")):
        rays = pinhole_rays(Ks[c], (w, h), supersample)
        for i in range(frames):
            tr = time.perf_counter()
            img, d_range = render_room_view(
                room,
                rays,
                poses[c][i],
                supersample=supersample,
                noise_sigma=noise_sigma,
                rng=np.random.default_rng([seed, 50, c, i]),
            )
            t_render += time.perf_counter() - tr
            atomic_write_bytes(out / name / f"img_{i:05d}.png", _encode_png(img))
            depth[name].append([round(v, 4) for v in d_range])
    write_tum(out / "truth_a.tum", stamps, poses[0])
    write_tum(out / "truth_b.tum", stamps, poses[1])
    T_a_b = motion.T_a_b(stamps)
    T_w_b_sync = poses[0] @ T_a_b
    body = {
        "scenario": SCENARIO,
        "seed": int(seed),
        "n_frames": int(frames),
        "image_size": [w, h],
        "fps": float(fps),
        "timestamps": "frame index / fps, seconds, on each camera's own clock (the index is "
        "in the file name)",
        "time_offset_s": float(time_offset_s),
        "time_offset": "camera B's clock minus camera A's (as acscal's time_offset_s): B's "
        "image stamped t shows the rig at time t - time_offset_s (A's image stamped t shows "
        "it at t)",
        "room": {
            "size": room.size,
            "frame": "origin at a floor corner, x along the length, y along the width, z up",
            "faces": list(FACES),
            "face_planes": "wall_x0: x = 0, wall_x1: x = length, wall_y0: y = 0, "
            "wall_y1: y = width, floor: z = 0, ceiling: z = height",
            "texel": room.texel,
            "lamp": room.lamp,
            "texture": "multi-octave value noise, blobs, strokes and speckles under a varying "
            "contrast, Lambertian shading from the lamp baked in; not periodic",
        },
        "cam_a": _cam_doc("cam_a", Ks[0], (w, h), poses[0], rig_times[0], depth["cam_a"]),
        "cam_b": _cam_doc("cam_b", Ks[1], (w, h), poses[1], rig_times[1], depth["cam_b"]),
        "joint": {
            "type": "ball",
            "position_in_a": motion.rig.o_a,
            "position_in_b": motion.rig.o_b,
            "position_in_world": se3.transform_points(poses[0], motion.rig.o_a),
        },
        "rest_rotation_R_a_b": motion.rig.R0,
        "relative_pose": {
            "reference": 0,
            "T_b_a": se3.invert_transforms(T_a_b[0]),
            "rpy_deg": se3.rpy_deg_from_matrix(T_a_b[0][:3, :3]),
            "translation_b_in_a": T_a_b[0][:3, 3],
        },
        "T_a_b": T_a_b,
        "T_world_b_at_a_times": T_w_b_sync,
        "T_wb_wa": np.eye(4),
        "motion": _motion_summary(motion, rig_times[0], rig_times[1], room),
        "render": {
            "supersample": supersample,
            "anti_aliasing": f"{supersample}x{supersample} samples a pixel, averaged; "
            "textures bilinear, blurred 0.6 texel",
            "noise_sigma": float(noise_sigma),
            "seconds_per_image": round(t_render / (2 * frames), 4),
            "seconds_textures": round(t_room, 2),
            "seconds_total": round(time.perf_counter() - t0, 2),
        },
    }
    header = make_header(
        TRUTH_KIND,
        inputs={},
        method=(
            f"rendered markerless ACS in a textured room (sample_data_gen.textured): seed "
            f"{seed}, {frames} frames, {w}x{h}, {fps} fps, time offset {time_offset_s} s"
        ),
        units={"length": "metres", "angles": "deg", "time": "s", "intensity": "grey levels"},
        frames={
            "cam_a.T_world_cam": "camera A in the room frame (world), at its images",
            "cam_b.T_world_cam": "camera B in the room frame (world), at its images",
            "T_a_b": "maps b to a, per frame, at rig time i / fps (camera A's images)",
            "T_world_b_at_a_times": "camera B in the room frame at rig time i / fps",
            "relative_pose.T_b_a": "maps a to b at the reference instant (paper's H_BA)",
            "joint.position_in_a": "a",
            "joint.position_in_b": "b",
            "joint.position_in_world": "room frame, per frame, at rig time i / fps",
            "T_wb_wa": "maps world_a to world_b (both are the room frame)",
        },
    )
    write_yaml_artifact(out / "truth.yaml", header, body)
    return out


def _cam_doc(
    name: str,
    K: FloatArray,
    size: tuple[int, int],
    T_world_cam: FloatArray,
    rig_times: FloatArray,
    depth: list[list[float]],
) -> dict[str, Any]:
    """A camera's entry in ``truth.yaml``."""
    return {
        "model": "pinhole",
        "image_size": list(size),
        "K": K,
        "dist": np.zeros(5),
        "dist_order": "k1 k2 p1 p2 k3 (OpenCV)",
        "images": f"{name}/img_{{index:05d}}.png",
        "truth_trajectory": f"truth_{name[-1]}.tum",
        "world": "the room frame",
        "T_world_cam": T_world_cam,
        "rig_time_s": rig_times,
        "depth_range_m": depth,
    }
