"""The report's figures, drawn with matplotlib's Agg canvas (no pyplot, no display).

Every function takes arrays and returns the PNG's bytes. 3-D views show camera frames
(OpenCV: x right, y down, z forward) with ``-y`` up: a point ``(x, y, z)`` is drawn at
``(x, z, -y)``.
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from acs_cli.core.se3 import FloatArray
from acs_cli.report.verdict import COVERAGE_GRID

__all__ = [
    "AngleSeries",
    "CameraView",
    "CornerErrorData",
    "CoverageData",
    "ReprojectionData",
    "ResidualSeries",
    "angles_figure",
    "camera_name",
    "corner_errors_figure",
    "coverage_counts",
    "coverage_figure",
    "coverage_fraction",
    "reprojection_figure",
    "residuals_figure",
    "rig_of_many_figure",
    "rig_reference_figure",
    "rig_trajectory_figure",
]

COLOR_A = "#1f77b4"
COLOR_B = "#ff7f0e"
COLOR_JOINT = "#2ca02c"
COLOR_REJECTED = "#d62728"
#: Camera frame -> display frame: (x, y, z) -> (x, z, -y), so that "up" is up.
_DISPLAY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def camera_name(camera: str) -> str:
    """How a camera is named in the report: a pair's ``a`` and ``b`` as ``A`` and ``B``, a
    rig's cameras by their names (``camera {camera_name(c)}``)."""
    return camera.upper() if camera in ("a", "b") else camera


def camera_colors(cameras: Iterable[str]) -> dict[str, str]:
    """The colour of each camera of a rig, in the rig figure's order (matplotlib's cycle
    ``C0``, ``C1``, ...): the other figures draw a rig's cameras in the same colours."""
    return {c: f"C{i % 10}" for i, c in enumerate(cameras)}


def _color(camera: str, color: str | None) -> str:
    """A camera's colour: its own, else a pair's (A blue, B orange)."""
    return color or (COLOR_A if camera == "a" else COLOR_B)


@dataclass(frozen=True)
class CameraView:
    """How to draw a camera's frustum: its image size and camera matrix (pixels).

    Without them a 4:3 image with a focal length equal to its width is drawn.
    """

    image_size: tuple[int, int] = (640, 480)
    camera_matrix: FloatArray | None = None


@dataclass(frozen=True)
class ResidualSeries:
    """One panel of the joint-constraint residual figure.

    Attributes
    ----------
    title : str
    x : ndarray, shape (n,)
        Timestamps (s) or frame numbers.
    values : ndarray, shape (n,)
        Residual per frame, in ``unit``.
    rejected : ndarray of bool, shape (n,)
        Frames the estimator rejected as outliers.
    unit : str
    """

    title: str
    x: FloatArray
    values: FloatArray
    rejected: np.ndarray
    unit: str


@dataclass(frozen=True)
class AngleSeries:
    """One panel of the joint-angle figure: a joint's angles over time.

    Attributes
    ----------
    title : str
    x : ndarray, shape (n,)
        Timestamps (s) or frame numbers.
    values : ndarray, shape (n, k)
        ``k`` angles per frame (deg): a hinge's angle, a ball's rotation vector.
    labels : tuple of str
        The ``k`` curves' names.
    rejected : ndarray of bool, shape (n,)
        Frames the estimator rejected as outliers.
    zero : float or None
        The time at which the angles are zero (the reference instant), if among ``x``.
    """

    title: str
    x: FloatArray
    values: FloatArray
    labels: tuple[str, ...]
    rejected: np.ndarray
    zero: float | None = None


@dataclass(frozen=True)
class ReprojectionData:
    """One camera's reprojection errors.

    Attributes
    ----------
    camera : str
    view_names : list of str
        Views of the intrinsics calibration.
    view_rms : ndarray, shape (v,)
        Their RMS reprojection error (px).
    overall_rms : float or None
        The calibration's RMS (px).
    poses : dict of str to ndarray
        Per-image RMS (px) of each poses file, by file name.
    pose_images : dict of str to list of str
        The image names of each poses file (when it records them), as ``poses``.
    color : str or None
        The camera's colour (None: a pair's, A blue and B orange).
    """

    camera: str
    view_names: list[str] = field(default_factory=list)
    view_rms: FloatArray = field(default_factory=lambda: np.zeros(0))
    overall_rms: float | None = None
    poses: dict[str, FloatArray] = field(default_factory=dict)
    pose_images: dict[str, list[str]] = field(default_factory=dict)
    color: str | None = None


@dataclass(frozen=True)
class CoverageData:
    """One camera's detected corners over its image.

    Attributes
    ----------
    camera : str
    corners : ndarray, shape (k, 2)
        Every detected corner (pixels).
    image_size : tuple of int
        ``(width, height)`` in pixels.
    """

    camera: str
    corners: FloatArray
    image_size: tuple[int, int]


@dataclass(frozen=True)
class CornerErrorData:
    """One camera's per-corner reprojection errors.

    Attributes
    ----------
    camera : str
    positions : ndarray, shape (k, 2)
        The detected corners (pixels).
    residuals : ndarray, shape (k, 2)
        Detected minus projected (pixels).
    centre : ndarray, shape (2,)
        The principal point ``(cx, cy)`` (pixels), the centre of the radial plot.
    color : str or None
        The camera's colour (None: a pair's, A blue and B orange).
    """

    camera: str
    positions: FloatArray
    residuals: FloatArray
    centre: FloatArray
    color: str | None = None


def _png(fig: Figure, dpi: int) -> bytes:
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


def _frustum_points(view: CameraView, size: float) -> FloatArray:
    """Centre and the four image corners at depth ``size`` in the camera frame, ``(5, 3)``."""
    w, h = view.image_size
    K = view.camera_matrix
    if K is None:
        K = np.array([[w, 0.0, w / 2.0], [0.0, w, h / 2.0], [0.0, 0.0, 1.0]])
    u = np.array([0.0, w, w, 0.0])
    v = np.array([0.0, 0.0, h, h])
    x = (u - K[0, 2]) / K[0, 0]
    y = (v - K[1, 2]) / K[1, 1]
    corners = np.column_stack([x, y, np.ones(4)]) * size / np.hypot(x, y).max(initial=1.0)
    return np.vstack([np.zeros(3), corners])


def _frustum_segments(T: FloatArray, view: CameraView, size: float) -> FloatArray:
    """Line segments ``(n * 9, 2, 3)`` of frustums at poses ``T`` ``(n, 4, 4)`` (display frame)."""
    P = _frustum_points(view, size)
    W = np.einsum("nij,kj->nki", T[:, :3, :3], P) + T[:, None, :3, 3]  # (n, 5, 3)
    W = W @ _DISPLAY.T
    edges = [(0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1)]
    segs = np.stack([np.stack([W[:, i], W[:, j]], axis=1) for i, j in edges], axis=1)
    # a short tick from the image's top edge marks "up" in the image (-y)
    top = (W[:, 1] + W[:, 2]) / 2.0
    tick = top + (W[:, 1] - W[:, 4]) * 0.3
    segs = np.concatenate([segs, np.stack([top, tick], axis=1)[:, None]], axis=1)
    return segs.reshape(-1, 2, 3)


def _disp(p: FloatArray) -> FloatArray:
    return np.asarray(p, dtype=float) @ _DISPLAY.T


def _equal_axes(ax: Any, pts: FloatArray) -> None:
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid = (lo + hi) / 2.0
    half = max(float((hi - lo).max()) / 2.0, 1e-6) * 1.05
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel("x")
    ax.set_ylabel("z (A forward)")
    ax.set_zlabel("-y (up)")
    ax.tick_params(labelsize=7)


def _subsample(n: int, max_count: int, keep: int) -> np.ndarray:
    idx = np.unique(np.linspace(0, n - 1, min(n, max_count)).round().astype(int))
    return np.union1d(idx, [keep])


def rig_trajectory_figure(
    T_r_a: FloatArray,
    T_r_b: FloatArray,
    joint_from_a: FloatArray,
    joint_from_b: FloatArray,
    reference: int,
    unit: str,
    views: tuple[CameraView, CameraView] = (CameraView(), CameraView()),
    max_frustums: int = 25,
    dpi: int = 100,
) -> bytes:
    """The rig's recovered trajectory in 3-D, seen from two directions.

    Parameters
    ----------
    T_r_a, T_r_b : ndarray, shape (n, 4, 4)
        Camera A's and B's poses in camera A's frame at the reference instant.
    joint_from_a, joint_from_b : ndarray, shape (n, 3)
        The joint as each camera sees it (same frame and unit).
    reference : int
        The reference frame (drawn in bold).
    unit : str
        Length unit, for the title.
    views : pair of CameraView
    max_frustums : int
        At most this many frustums per camera (evenly spaced frames, plus the reference).
    dpi : int

    Returns
    -------
    bytes
        A PNG.
    """
    n = T_r_a.shape[0]
    c_a, c_b = T_r_a[:, :3, 3], T_r_b[:, :3, 3]
    pts = np.vstack([c_a, c_b, joint_from_a, joint_from_b])
    extent = float(np.ptp(pts, axis=0).max()) if n > 1 else 1.0
    rig = float(np.linalg.norm(c_a - joint_from_a, axis=1).mean() + 1e-9)
    size = max(min(0.12 * extent, 0.5 * rig), 1e-3)
    idx = _subsample(n, max_frustums, reference)
    fig = Figure(figsize=(11.0, 5.4))
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.16, top=0.9, wspace=0.12)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ja, jb = _disp(joint_from_a), _disp(joint_from_b)
    all_segs = [_disp(pts)]
    for T, color, label, view in (
        (T_r_a, COLOR_A, "camera A", views[0]),
        (T_r_b, COLOR_B, "camera B", views[1]),
    ):
        segs = _frustum_segments(T[idx], view, size)
        all_segs.append(segs.reshape(-1, 3))
        ax.add_collection3d(Line3DCollection(segs, colors=color, linewidths=0.7, label=label))
    links = np.concatenate([np.stack([_disp(c[idx]), ja[idx]], axis=1) for c in (c_a, c_b)], axis=0)
    ax.add_collection3d(Line3DCollection(links, colors="#999999", linewidths=0.5))
    ax.plot(ja[:, 0], ja[:, 1], ja[:, 2], "o-", color=COLOR_JOINT, ms=3, lw=1.5,
            label="joint (as A sees it)")  # fmt: skip
    ax.plot(jb[:, 0], jb[:, 1], jb[:, 2], "x", color="#145214", ms=5,
            label="joint (as B sees it)")  # fmt: skip
    ref = np.stack([_disp(c_a[reference]), ja[reference], _disp(c_b[reference])])
    ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], color="black", lw=2.2, label="rig at the reference")
    _equal_axes(ax, np.vstack(all_segs))
    ax.view_init(elev=22.0, azim=-60.0)
    ax.set_title("3-D view (-y up)", fontsize=9)
    fig.legend(*ax.get_legend_handles_labels(), loc="lower center", ncol=5, fontsize=8)

    # top view: camera A's x (right) against z (forward), looking down its -y axis
    top = fig.add_subplot(1, 2, 2)
    arrow = size * 1.2
    for T, color in ((T_r_a, COLOR_A), (T_r_b, COLOR_B)):
        c = T[:, :3, 3]
        z = T[:, :3, 2]
        top.plot(c[:, 0], c[:, 2], ".", color=color, ms=5)
        dirs = np.stack([c[idx][:, [0, 2]], (c[idx] + arrow * z[idx])[:, [0, 2]]], axis=1)
        top.add_collection(LineCollection(list(dirs), colors=color, linewidths=0.8))
    top.plot(joint_from_a[:, 0], joint_from_a[:, 2], "o-", color=COLOR_JOINT, ms=3, lw=1.2)
    top.plot(joint_from_b[:, 0], joint_from_b[:, 2], "x", color="#145214", ms=5)
    r = np.stack([c_a[reference], joint_from_a[reference], c_b[reference]])
    top.plot(r[:, 0], r[:, 2], color="black", lw=2.2)
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel(f"x ({unit})", fontsize=8)
    top.set_ylabel(f"z, camera A forward ({unit})", fontsize=8)
    top.tick_params(labelsize=7)
    top.grid(alpha=0.3)
    top.set_title("from above (x-z plane; ticks: viewing directions)", fontsize=9)
    fig.suptitle(
        f"ACS trajectory in camera A's frame at the reference instant (frame {reference}), "
        f"{n} frames, lengths in {unit}",
        fontsize=10,
    )
    return _png(fig, dpi)


def rig_reference_figure(
    T_a_b: FloatArray,
    position_in_a: FloatArray,
    joint_from_b: FloatArray,
    unit: str,
    views: tuple[CameraView, CameraView] = (CameraView(), CameraView()),
    dpi: int = 100,
) -> bytes:
    """The rig at the reference instant: both cameras, their axes and the joint.

    Parameters
    ----------
    T_a_b : ndarray, shape (4, 4)
        Camera B's pose in camera A's frame (A's units).
    position_in_a : ndarray, shape (3,)
        The joint in A's frame.
    joint_from_b : ndarray, shape (3,)
        The joint as B sees it, in A's frame (``T_a_b @ o_b``).
    unit : str
    views : pair of CameraView
    dpi : int
    """
    T = np.stack([np.eye(4), np.asarray(T_a_b, dtype=float)])
    o_a = np.asarray(position_in_a, dtype=float)
    o_b = np.asarray(joint_from_b, dtype=float)
    span = max(float(np.linalg.norm(o_a)), float(np.linalg.norm(T[1, :3, 3])), 1e-6)
    size = 0.25 * span
    fig = Figure(figsize=(6.4, 5.2))
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    pts = [np.zeros(3), T[1, :3, 3], o_a, o_b]
    for k, (color, name, view) in enumerate(((COLOR_A, "A", views[0]), (COLOR_B, "B", views[1]))):
        segs = _frustum_segments(T[k : k + 1], view, size)
        ax.add_collection3d(Line3DCollection(segs, colors=color, linewidths=1.2))
        pts.append(segs.reshape(-1, 3) @ _DISPLAY)  # back to camera coordinates
        c = T[k, :3, 3]
        for axis, axis_color in zip(range(3), ("#d62728", "#2ca02c", "#1f77b4"), strict=True):
            tip = _disp(c + T[k, :3, axis] * size * 0.8)
            cc = _disp(c)
            ax.plot([cc[0], tip[0]], [cc[1], tip[1]], [cc[2], tip[2]], color=axis_color, lw=1.2)
        cd = _disp(c)
        ax.text(cd[0], cd[1], cd[2], f"  camera {name}", color=color, fontsize=9)
        link = np.stack([cd, _disp(o_a if k == 0 else o_b)])
        ax.plot(link[:, 0], link[:, 1], link[:, 2], color=color, lw=2.5, alpha=0.7)
    ja, jb = _disp(o_a), _disp(o_b)
    ax.scatter([ja[0]], [ja[1]], [ja[2]], color=COLOR_JOINT, s=60, label="joint (o_a)")
    ax.scatter(
        [jb[0]], [jb[1]], [jb[2]], color="#145214", marker="x", s=50, label="joint (T_a_b o_b)"
    )
    _equal_axes(ax, _disp(np.vstack([np.atleast_2d(p) for p in pts])))
    ax.view_init(elev=20.0, azim=-60.0)
    ax.legend(loc="upper left", fontsize=7)
    ax.set_title(
        f"The rig at the reference instant (axes: x red, y green, z blue)\n"
        f"|B's origin in A| = {np.linalg.norm(T[1, :3, 3]):.4g} {unit}",
        fontsize=9,
    )
    return _png(fig, dpi)


def rig_of_many_figure(
    T_ref_cam: dict[str, FloatArray],
    joints: Sequence[tuple[str, str, str, str, FloatArray | None]],
    paths: dict[str, FloatArray],
    instants: FloatArray,
    at_instants: dict[str, FloatArray],
    reference: str,
    unit: str,
    dpi: int = 100,
) -> bytes:
    """A rig of many cameras in 3-D: left, each camera (frustum and name) at the reference
    instant and each joint as a link through its point (rigid edges dashed); right, the rig
    as a stick figure at a few instants, coloured by time, over each camera's path.

    Parameters
    ----------
    T_ref_cam : dict of str to ndarray, shape (4, 4)
        Camera poses in the reference camera's frame at the reference instant.
    joints : sequence of (name, type, p, q, point)
        ``point`` ``(3,)`` in the same frame, or None for a rigid edge.
    paths : dict of str to ndarray, shape (n, 3)
        Cameras' and joints' positions over time in the reference camera's frame at each
        instant (NaN where none): drawn as dots on the right.
    instants : ndarray, shape (k,)
        The times at which to draw the rig on the right (none: no right panel).
    at_instants : dict of str to ndarray, shape (k, 3)
        ``paths`` at ``instants``: the rig drawn as links, coloured by time.
    reference : str
        The reference camera (whose frame the right panel is in).
    unit : str
    dpi : int

    Returns
    -------
    bytes
        A PNG.
    """
    centres = {c: T[:3, 3] for c, T in T_ref_cam.items()}
    pts = np.vstack([*centres.values(), *[j[4] for j in joints if j[4] is not None]])
    extent = float(np.ptp(pts, axis=0).max()) if pts.shape[0] > 1 else 1.0
    size = max(0.08 * extent, 1e-3)
    colors = camera_colors(T_ref_cam)
    over_time = instants.size > 0 and bool(at_instants)
    fig = Figure(figsize=(11.0, 5.6) if over_time else (6.4, 5.6))
    fig.subplots_adjust(left=0.02, right=0.94 if over_time else 0.98, bottom=0.06, top=0.9,
                        wspace=0.08)  # fmt: skip
    ax = fig.add_subplot(1, 2 if over_time else 1, 1, projection="3d")
    segs_all = [_disp(pts)]
    for c, T in T_ref_cam.items():
        segs = _frustum_segments(T[None], CameraView(), size)
        segs_all.append(segs.reshape(-1, 3))
        ax.add_collection3d(Line3DCollection(segs, colors=colors[c], linewidths=0.9))
        d = _disp(centres[c][None])[0]
        ax.text(d[0], d[1], d[2], f" {c}", fontsize=8, color=colors[c])
    for name, jtype, p, q, point in joints:
        a, b = _disp(centres[p][None])[0], _disp(centres[q][None])[0]
        if point is None:
            ax.plot(*np.stack([a, b]).T, "--", color="#555555", lw=1.2)
            continue
        j = _disp(point[None])[0]
        ax.plot(*np.stack([a, j, b]).T, "-", color=COLOR_JOINT, lw=1.6)
        ax.plot([j[0]], [j[1]], [j[2]], "o", color=COLOR_JOINT, ms=5)
        ax.text(j[0], j[1], j[2], f" {name} ({jtype})", fontsize=7, color="#145214")
    _equal_axes(ax, np.vstack(segs_all))
    ax.set_ylabel("z (ref. forward)")
    ax.view_init(elev=22.0, azim=-60.0)
    ax.set_title("the rig at the reference instant", fontsize=9)
    if over_time:
        _rig_over_time(fig, colors, joints, paths, instants, at_instants, reference)
    fig.suptitle(f"Cameras and joints in the reference camera's frame ({unit}; -y up)", fontsize=10)
    return _png(fig, dpi)


def _rig_over_time(
    fig: Figure,
    colors: dict[str, str],
    joints: Sequence[tuple[str, str, str, str, FloatArray | None]],
    paths: dict[str, FloatArray],
    instants: FloatArray,
    at_instants: dict[str, FloatArray],
    reference: str,
) -> None:
    """The right panel of :func:`rig_of_many_figure`: the rig at ``instants``."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    ax = fig.add_subplot(1, 2, 2, projection="3d")
    lo, hi = float(instants.min()), float(instants.max())
    norm = Normalize(lo, hi if hi > lo else lo + 1.0)
    cmap = colormaps["viridis"]
    at = {n: _disp(x) for n, x in at_instants.items()}
    seen = [_disp(x[np.isfinite(x).all(axis=1)]) for x in paths.values()]
    for name, x in paths.items():
        pp = _disp(x)
        color = colors.get(name, "#145214")  # a joint's point: dark green
        ax.plot(pp[:, 0], pp[:, 1], pp[:, 2], ".", color=color, ms=2.0, alpha=0.5)
    for k, t in enumerate(instants):
        tint = cmap(norm(t))
        for name, _, p, q, point in joints:
            via = [] if point is None else [name]  # a rigid pair: no point between them
            if any(b not in at for b in (p, q, *via)):
                continue
            xyz = np.stack([at[b][k] for b in (p, *via, q)])
            if np.isfinite(xyz).all():
                ax.plot(*xyz.T, "--" if point is None else "-", color=tint, lw=1.4)
                if point is not None:
                    ax.plot(*xyz[1:2].T, "o", color=tint, ms=3.5)
        for c, color in colors.items():
            x = at[c][k] if c in at else np.full(3, np.nan)
            if np.isfinite(x).all():
                ax.plot([x[0]], [x[1]], [x[2]], "o", color=color, ms=4.5, mec="black", mew=0.4)
    _equal_axes(ax, np.vstack(seen))
    ax.set_ylabel("z (ref. forward)")
    ax.view_init(elev=22.0, azim=-60.0)
    ax.set_title(
        f"how the rig bends: every frame in {reference}'s frame at that instant\n(small dots: "
        f"cameras and joints; links: the rig at {instants.size} instants, coloured by time)",
        fontsize=9,
    )
    fig.colorbar(ScalarMappable(norm, cmap), ax=ax, shrink=0.55, pad=0.08,
                 label="time (s) or frame")  # fmt: skip


def angles_figure(series: Sequence[AngleSeries], dpi: int = 100) -> bytes:
    """One panel per joint: its angles over time, the reference instant (their zero) and
    the frames rejected as outliers marked.

    Parameters
    ----------
    series : sequence of AngleSeries
        At least one.
    dpi : int
    """
    n = len(series)
    height = 2.5 * n + 0.6
    fig = Figure(figsize=(10.0, height))
    fig.subplots_adjust(left=0.07, right=0.8, top=1 - 0.35 / height,
                        bottom=0.5 / height + 0.02, hspace=0.5)  # fmt: skip
    axes = fig.subplots(n, 1, squeeze=False)[:, 0]
    for ax, s in zip(axes, series, strict=True):
        v = np.asarray(s.values, dtype=float).reshape(s.x.size, -1)
        for k, label in enumerate(s.labels):
            ax.plot(s.x, v[:, k], "o-", color=f"C{k}", ms=2.5, lw=0.8, label=label)
        if s.rejected.any():
            xr = np.repeat(s.x[s.rejected], v.shape[1])
            ax.plot(xr, v[s.rejected].reshape(-1), "X", color=COLOR_REJECTED, ms=7,
                    label="rejected as outlier")  # fmt: skip
        if s.zero is not None:
            ax.axvline(s.zero, color="#555555", ls=":", lw=1.0, label="zero (reference instant)")
        ax.axhline(0.0, color="#999999", lw=0.6)
        ax.set_title(s.title, fontsize=9, loc="left")
        ax.set_ylabel("deg")
        ax.tick_params(labelsize=8)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("timestamp (s) or frame number")
    return _png(fig, dpi)


def residuals_figure(
    series: Sequence[ResidualSeries], dpi: int = 100, scale_to_used: bool = False
) -> bytes:
    """One panel per residual series: the residual per frame, rejected frames marked.

    Parameters
    ----------
    series : sequence of ResidualSeries
        At least one.
    dpi : int
    scale_to_used : bool
        Scale each panel to the frames used: a rejected frame far above them is drawn at
        the panel's top edge with its value written beside it (a gross outlier would
        otherwise flatten the others).
    """
    n = len(series)
    fig = Figure(figsize=(9.0, 2.3 * n + 0.6))
    fig.subplots_adjust(
        left=0.08,
        right=0.98,
        top=1 - 0.35 / (2.3 * n + 0.6),
        bottom=0.5 / (2.3 * n + 0.6) + 0.02,
        hspace=0.45,
    )
    axes = fig.subplots(n, 1, squeeze=False)[:, 0]
    for ax, s in zip(axes, series, strict=True):
        ok = ~s.rejected
        ax.plot(s.x, s.values, "-", color="#999999", lw=0.8)
        ax.plot(s.x[ok], s.values[ok], "o", color=COLOR_A, ms=4, label="used")
        if s.rejected.any():
            ax.plot(
                s.x[~ok],
                s.values[~ok],
                "X",
                color=COLOR_REJECTED,
                ms=8,
                label="rejected as outlier",
            )
        if ok.any():
            rms = float(np.sqrt(np.mean(s.values[ok] ** 2)))
            ax.axhline(rms, color="#555555", ls="--", lw=0.8, label=f"RMS {rms:.3g} {s.unit}")
        ax.set_title(s.title, fontsize=9, loc="left")
        ax.set_ylabel(s.unit)
        ax.set_ylim(bottom=0.0)
        if scale_to_used and ok.any():
            _clip_outliers(ax, s, 1.25 * float(np.nanmax(s.values[ok])))
        ax.tick_params(labelsize=8)
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("timestamp (s) or frame number")
    return _png(fig, dpi)


def _clip_outliers(ax: Any, s: ResidualSeries, top: float) -> None:
    """Limit ``ax`` to ``top`` (when a rejected frame lies above it) and mark each frame
    above at the top edge, its value beside it."""
    over = s.rejected & (s.values > top)
    if top <= 0.0 or not over.any():
        return
    ax.set_ylim(0.0, top)
    ax.plot(s.x[over], np.full(int(over.sum()), top), "^", color=COLOR_REJECTED, ms=7,
            clip_on=False, label="rejected, off the scale")  # fmt: skip
    for x, v in zip(s.x[over], s.values[over], strict=True):
        ax.annotate(f" {v:.3g}", (x, top), xytext=(3, -9), textcoords="offset points",
                    fontsize=7, color=COLOR_REJECTED)  # fmt: skip


#: Inches of figure height per bar of a per-view chart.
_BAR_INCH = 0.16


def reprojection_figure(cameras: Sequence[ReprojectionData], dpi: int = 100) -> bytes:
    """Per camera: RMS reprojection error of each calibration view and of each posed image.

    The views are horizontal bars, one labelled row each (the figure grows with their
    number, so 40 or more stay readable); the posed images are points per poses file.

    Parameters
    ----------
    cameras : sequence of ReprojectionData
        At least one.
    dpi : int
    """
    heights = [max(2.4, _BAR_INCH * cam.view_rms.size + 0.9) for cam in cameras]
    height = sum(heights) + 0.8 * len(cameras) + 0.4
    longest = max((len(v) for cam in cameras for v in cam.view_names), default=0)
    fig = Figure(figsize=(10.0, height))
    grid = fig.add_gridspec(
        len(cameras), 2, height_ratios=heights, left=min(0.05 + 0.0085 * longest, 0.3),
        right=0.98, bottom=0.7 / height, top=1 - 0.3 / height, hspace=0.8 / np.mean(heights),
        wspace=0.3,
    )  # fmt: skip
    for k, cam in enumerate(cameras):
        ax = fig.add_subplot(grid[k, 0])
        if cam.view_rms.size:
            y = np.arange(cam.view_rms.size)
            ax.barh(y, cam.view_rms, color=_color(cam.camera, cam.color))
            if cam.overall_rms is not None:
                ax.axvline(cam.overall_rms, color="black", ls="--", lw=0.8)
            ax.set_yticks(y, cam.view_names, fontsize=6)
            ax.set_ylim(cam.view_rms.size - 0.5, -0.5)
            ax.set_xlabel("RMS (px)", fontsize=8)
        else:
            ax.text(
                0.5, 0.5, "no intrinsics.yaml", ha="center", va="center", transform=ax.transAxes
            )
        overall = "" if cam.overall_rms is None else f" (dashed: RMS {cam.overall_rms:.3g} px)"
        ax.set_title(
            f"camera {camera_name(cam.camera)}: intrinsics calibration, per view{overall}",
            fontsize=9,
            loc="left",
        )
        ax.tick_params(axis="x", labelsize=8)
        ax.grid(axis="x", alpha=0.3)
        ax = fig.add_subplot(grid[k, 1])
        if cam.poses:
            for j, (name, rms) in enumerate(sorted(cam.poses.items())):
                ax.plot(np.arange(rms.size), rms, "o-", ms=3, lw=0.8, label=name, color=f"C{j}")
            ax.legend(fontsize=7)
            ax.set_xlabel("posed image (index in the file)", fontsize=8)
        else:
            ax.text(0.5, 0.5, "no poses file", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(
            f"camera {camera_name(cam.camera)}: board poses (PnP), per image",
            fontsize=9,
            loc="left",
        )
        ax.set_ylabel("RMS (px)")
        ax.set_ylim(bottom=0.0)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
    return _png(fig, dpi)


def corner_errors_figure(cameras: Sequence[CornerErrorData], dpi: int = 100) -> bytes:
    """Per camera: every corner's reprojection error as a vector, against its distance from
    the principal point, and as a histogram.

    A wrong distortion model shows as errors that grow, or turn, with the distance from the
    centre; a good fit as a round cloud and a flat radial trend.

    Parameters
    ----------
    cameras : sequence of CornerErrorData
        At least one.
    dpi : int
    """
    n = len(cameras)
    fig = Figure(figsize=(11.0, 3.4 * n + 0.3))
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.6 / (3.4 * n + 0.3),
                        top=1 - 0.45 / (3.4 * n + 0.3), hspace=0.55, wspace=0.3)  # fmt: skip
    axes = fig.subplots(n, 3, squeeze=False)
    for row, cam in zip(axes, cameras, strict=True):
        color = _color(cam.camera, cam.color)
        e = np.asarray(cam.residuals, dtype=float).reshape(-1, 2)
        mag = np.hypot(e[:, 0], e[:, 1])
        rms = float(np.sqrt(np.mean(mag**2))) if mag.size else float("nan")
        who = f"camera {camera_name(cam.camera)}"
        ax = row[0]
        ax.scatter(e[:, 0], e[:, 1], s=3, color=color, alpha=0.4, linewidths=0)
        lim = max(float(np.abs(e).max(initial=0.0)) * 1.1, 1e-3)
        ax.set_xlim(-lim, lim)
        ax.set_ylim(lim, -lim)
        ax.set_aspect("equal")
        ax.axhline(0.0, color="#999999", lw=0.6)
        ax.axvline(0.0, color="#999999", lw=0.6)
        ax.set_xlabel("error u (px)", fontsize=8)
        ax.set_ylabel("error v (px)", fontsize=8)
        ax.set_title(f"{who}: {mag.size} corners, RMS {rms:.3g} px", fontsize=9, loc="left")
        ax = row[1]
        r = np.hypot(*(np.asarray(cam.positions, dtype=float) - cam.centre).T)
        ax.scatter(r, mag, s=3, color=color, alpha=0.4, linewidths=0)
        if r.size:
            edges = np.linspace(0.0, float(r.max()) + 1e-9, 11)
            idx = np.digitize(r, edges) - 1
            mids, med = [], []
            for b in range(10):
                sel = idx == b
                if sel.sum() >= 3:
                    mids.append((edges[b] + edges[b + 1]) / 2.0)
                    med.append(float(np.median(mag[sel])))
            ax.plot(mids, med, "-o", color="black", ms=3, lw=1.0, label="median per ring")
            ax.legend(fontsize=7, loc="upper left")
        ax.set_ylim(bottom=0.0)
        ax.set_xlabel("distance from the principal point (px)", fontsize=8)
        ax.set_ylabel("|error| (px)", fontsize=8)
        ax.set_title(f"{who}: error against radius", fontsize=9, loc="left")
        ax = row[2]
        ax.hist(mag, bins=30, color=color)
        ax.set_xlabel("|error| (px)", fontsize=8)
        ax.set_ylabel("corners", fontsize=8)
        ax.set_title(f"{who}: histogram", fontsize=9, loc="left")
        for ax in row:
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    return _png(fig, dpi)


def coverage_counts(
    corners: FloatArray, image_size: tuple[int, int], grid: tuple[int, int] = COVERAGE_GRID
) -> FloatArray:
    """Detected corners per cell of a ``grid`` (cells across, down) over the image.

    Parameters
    ----------
    corners : ndarray, shape (k, 2)
        Pixels; NaN rows (corners not seen) are left out.
    image_size : (int, int)
        ``(width, height)``, pixels.
    grid : (int, int)

    Returns
    -------
    ndarray, shape (grid[1], grid[0])
        Counts, row by row from the image's top.
    """
    w, h = image_size
    pts = np.asarray(corners, dtype=float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    counts, _, _ = np.histogram2d(
        pts[:, 1], pts[:, 0], bins=(grid[1], grid[0]), range=((0, h), (0, w))
    )
    return counts


def coverage_fraction(corners: FloatArray, image_size: tuple[int, int]) -> float:
    """The share of the cells of :func:`coverage_counts` holding at least one corner."""
    return float((coverage_counts(corners, image_size) > 0).mean())


def coverage_figure(cameras: Sequence[CoverageData], dpi: int = 100) -> bytes:
    """Per camera: where in the image the board's corners were detected.

    A heat map of corner counts over the :data:`COVERAGE_GRID` of cells with every corner
    on top; the title gives the share of cells with at least one corner.

    Parameters
    ----------
    cameras : sequence of CoverageData
        At least one.
    dpi : int
    """
    n = len(cameras)
    fig = Figure(figsize=(5.2 * n, 4.4))
    fig.subplots_adjust(left=0.08, right=0.96, bottom=0.12, top=0.9, wspace=0.3)
    axes = fig.subplots(1, n, squeeze=False)[0]
    for ax, cam in zip(axes, cameras, strict=True):
        w, h = cam.image_size
        pts = np.asarray(cam.corners, dtype=float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        counts = coverage_counts(pts, cam.image_size)
        covered = float((counts > 0).mean()) * 100.0
        im = ax.imshow(
            counts, extent=(0, w, h, 0), cmap="viridis", interpolation="nearest", aspect="equal"
        )
        ax.scatter(pts[:, 0], pts[:, 1], s=1.0, color="white", alpha=0.5, linewidths=0)
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_title(
            f"camera {camera_name(cam.camera)}: {pts.shape[0]} corners, {covered:.0f}% of cells",
            fontsize=9,
        )
        ax.set_xlabel("u (px)", fontsize=8)
        ax.set_ylabel("v (px)", fontsize=8)
        ax.tick_params(labelsize=7)
        fig.colorbar(im, ax=ax, shrink=0.7, label="corners per cell")
    return _png(fig, dpi)
