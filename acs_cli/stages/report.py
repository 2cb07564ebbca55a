"""The report stage: ``acscal report RUN_DIR`` (and the end of ``acscal run``).

Reads what a run folder holds (``cam_<x>/intrinsics.yaml``, ``cam_<x>/*.npz`` poses,
``joint.yaml``, ``relpose.yaml``) through the typed artifacts of :mod:`acs_cli.io`, each
file once, into a :class:`~acs_cli.report.model.ReportModel` (:func:`build_report`): with
each stage's verdict (:mod:`acs_cli.report.verdict`), the final intrinsics and joint, and
every posed corner's reprojection error recomputed from the poses NPZs
(:mod:`acs_cli.report.corners`); then
:func:`~acs_cli.report.render.render_report` draws the figures and the self-contained HTML
page, written with the same figures as PNG files in ``<name>_files/`` beside it. A section
whose artifact is missing or unreadable is skipped with a note; a folder with no artifact at
all is an :class:`InputError`.

A rig run's folder (``rig.yaml``) is reported as a rig: its cameras and joints and how it
bends over time (``trajectories/``), each joint's residual per frame
(``joint_residuals.csv``), each ball and hinge joint's angles per frame, and each camera that
ran from images (``cam_<name>/``) as a pair's cameras are; no section of the pair's stages,
and none that does not apply.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

import acs_cli
from acs_cli.core import se3
from acs_cli.core.acs_trajectory import (
    fixed_joint_residuals,
    overlap_relative_pose,
    overlap_residuals,
    recover_trajectory,
)
from acs_cli.core.angles import (
    BallAngles,
    HingeAngles,
    articulation_from_orientations,
    ball_angles,
)
from acs_cli.core.quality import largest_std
from acs_cli.errors import AcsError, InputError
from acs_cli.io.atomic import (
    atomic_write_bytes,
    atomic_write_text,
    check_distinct_output,
    check_writable,
    resolve_output,
)
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.joint import BundleSection, FramesUsed, JointArtifact, JointSection, PoseNoise
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.rig import RigArtifact
from acs_cli.io.rig_residuals import RESIDUALS_FILE, read_joint_residuals
from acs_cli.io.trajectory import Trajectory, read_trajectory
from acs_cli.io.validate import TIME_TOL, listed_mask
from acs_cli.io.verdict import VerdictSection
from acs_cli.report import figures as F
from acs_cli.report import verdict as V
from acs_cli.report.corners import corner_residuals
from acs_cli.report.model import (
    ArtifactRow,
    Estimate,
    FinalChoice,
    ReportModel,
    RigOfManyView,
    RigTrajectory,
    display_unit,
)
from acs_cli.report.render import FIGURE_NAMES, render_report
from acs_cli.stages.common import PairedTrajectories, pair_loaded
from acs_cli.stages.trajectory import (
    DEFAULT_EULER,
    pair_angles,
    recover_from_relpose,
    rig_angles,
)

__all__ = [
    "FIGURE_NAMES",
    "ReportConfig",
    "ReportRun",
    "build_report",
    "figures_dir_for",
    "run_report",
]

CAMERAS = ("a", "b")


@dataclass(frozen=True)
class ReportConfig:
    """Options of the report.

    Attributes
    ----------
    dpi : int
        Resolution of the figures.
    max_frustums : int
        At most this many camera frustums per camera in the trajectory view.
    extra_warnings : tuple of str
        Warnings to list besides the artifacts' own (e.g. the error that stopped a run).
    """

    dpi: int = 100
    max_frustums: int = 25
    extra_warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class ReportRun:
    """What :func:`run_report` wrote.

    Attributes
    ----------
    output : Path
        The HTML file.
    figures_dir : Path
        The folder of the PNG figures.
    figures : list of Path
        The PNG files written, in the page's order.
    notes : list of str
        Sections skipped and why.
    warnings : list of str
        Every warning listed in the report.
    """

    output: Path
    figures_dir: Path
    figures: list[Path]
    notes: list[str]
    warnings: list[str]


def figures_dir_for(output: Path) -> Path:
    """The folder of a report's PNG figures: ``<name>_files`` beside it."""
    return output.with_name(f"{output.stem}_files")


# --------------------------------------------------------------------------- gathering


@dataclass
class _Found:
    """The artifacts of a run folder (the readable ones, each file read once), the notes on
    the others and the warnings met on the way."""

    run_dir: Path
    #: each camera's folder (``cam_a``, ``cam_b``; a rig's ``cam_<name>``), by camera
    dirs: dict[str, Path] = field(default_factory=dict)
    #: a rig's cameras' colours, as the rig's figure draws them (a pair's: none)
    colors: dict[str, str] = field(default_factory=dict)
    intrinsics: dict[str, IntrinsicsArtifact] = field(default_factory=dict)
    poses: dict[str, list[Path]] = field(default_factory=dict)
    joint: JointArtifact | None = None
    relpose: RelposeArtifact | None = None
    rig: RigArtifact | None = None
    notes: list[str] = field(default_factory=list)
    warnings: list[tuple[str, str]] = field(default_factory=list)
    any_file: bool = False
    #: Trajectory files read so far (each once, whole), by resolved path; an exception for
    #: one that could not be read.
    loaded: dict[Path, PosesArtifact | AcsError] = field(default_factory=dict)

    @property
    def cameras(self) -> list[str]:
        """The cameras whose folders the report reads, in order."""
        return list(self.dirs)

    def warn(self, source: str, text: str) -> None:
        if (source, text) not in self.warnings:
            self.warnings.append((source, text))

    def rel(self, path: Path | str | None) -> str:
        return _rel(Path(str(path)), self.run_dir)

    def load(self, path: Path) -> PosesArtifact:
        """A trajectory file, read at most once."""
        key = path.resolve()
        if key not in self.loaded:
            try:
                self.loaded[key] = PosesArtifact.load(path)
            except AcsError as exc:
                self.loaded[key] = exc
        got = self.loaded[key]
        if isinstance(got, AcsError):
            raise got
        return got

    def trajectory(self, path: Path) -> Trajectory:
        return self.load(path).trajectory


def _rel(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return str(path)


def _is_poses_npz(path: Path) -> bool:
    return path.suffix == ".npz" and not path.name.endswith(".detections.npz")


A = TypeVar("A", IntrinsicsArtifact, JointArtifact, RelposeArtifact, RigArtifact)


def _read_artifact(found: _Found, path: Path, cls: type[A]) -> A | None:
    if not path.is_file():
        return None
    found.any_file = True
    try:
        return cls.load(path)
    except AcsError as exc:
        found.notes.append(f"{_rel(path, found.run_dir)} could not be read: {exc.one_line()}")
        return None


def _camera_dirs(run_dir: Path, rig: RigArtifact | None) -> dict[str, Path]:
    """Each camera's folder: a pair's ``cam_a``, ``cam_b``; a rig's ``cam_<name>`` (in a rig
    of several recordings ``<recording>/cam_<name>``, the camera named ``recording/name``),
    where ``acscal run`` writes a camera's intrinsics and poses when it ran from images."""
    if rig is None:
        return {c: run_dir / f"cam_{c}" for c in CAMERAS}
    if rig.reference_recording is None:  # one recording: the folders at the top
        return {c: run_dir / f"cam_{c}" for c in rig.cameras}
    dirs = {f"{r}/{c}": run_dir / r / f"cam_{c}" for r in rig.recordings for c in rig.cameras}
    return {label: d for label, d in dirs.items() if d.is_dir()}  # not every body in each


def _gather(run_dir: Path) -> _Found:
    found = _Found(run_dir)
    found.rig = rig = _read_artifact(found, run_dir / "rig.yaml", RigArtifact)
    found.dirs = _camera_dirs(run_dir, rig)
    if rig is not None:
        # the rig's figure colours the cameras posed at the reference instant, in order
        posed = sorted(rig.cameras, key=lambda c: rig.cameras[c].T_cam_ref is None)
        color = F.camera_colors(posed)
        found.colors = {label: color[label.rsplit("/", 1)[-1]] for label in found.dirs}
    for cam, d in found.dirs.items():
        intr = _read_artifact(found, d / "intrinsics.yaml", IntrinsicsArtifact)
        if intr is not None:
            found.intrinsics[cam] = intr
        if d.is_dir():
            npzs = sorted(p for p in d.iterdir() if p.is_file() and _is_poses_npz(p))
            if npzs:
                found.any_file = True
                found.poses[cam] = npzs
    found.joint = _read_artifact(found, run_dir / "joint.yaml", JointArtifact)
    found.relpose = _read_artifact(found, run_dir / "relpose.yaml", RelposeArtifact)
    return found


#: The folder of a rig run's trajectories (:data:`acs_cli.stages.rig.TRAJECTORY_DIR`).
RIG_TRAJECTORIES = "trajectories"
#: At most this many instants at which the report draws a rig over time (and the reference).
RIG_INSTANTS = 6

#: A path over time: times ``(n,)`` (sorted) and poses ``(n, 4, 4)``.
TimedPoses = tuple[np.ndarray, np.ndarray]


def _rig_paths(found: _Found, rig: RigArtifact) -> dict[str, TimedPoses]:
    """Every camera's and joint's poses over time in the reference frame, from the run's
    ``trajectories/`` (each file read once, in time order); a file that cannot be read is
    noted."""
    paths: dict[str, TimedPoses] = {}
    folder = found.run_dir / RIG_TRAJECTORIES
    for name in [*rig.cameras, *rig.joints]:
        f = folder / f"{name}.tum"
        if not f.is_file():
            continue
        try:
            t = read_trajectory(f)
        except AcsError as exc:
            found.notes.append(f"{found.rel(f)} could not be read: {exc.one_line()}")
            continue
        order = np.argsort(t.timestamps, kind="stable")
        paths[name] = (t.timestamps[order], t.T_world_cam[order])
    return paths


def _positions_at(path: TimedPoses, at: np.ndarray) -> np.ndarray:
    """``(k, 3)``: the path's positions at the times ``at`` ``(k,)`` (within
    :data:`~acs_cli.io.validate.TIME_TOL`), NaN where it has no pose."""
    times, T = path
    out = np.full((at.size, 3), np.nan)
    if not times.size:
        return out
    i = np.minimum(np.searchsorted(times, at - TIME_TOL), times.size - 1)
    ok = np.abs(times[i] - at) <= TIME_TOL
    out[ok] = T[i[ok], :3, 3]
    return out


def _in_body(paths: dict[str, TimedPoses], body: str) -> dict[str, np.ndarray]:
    """Every path's positions in ``body``'s frame at each of its instants, ``(n, 3)`` over
    ``body``'s ``n`` times (NaN where a path has no pose): how the rig bends about it."""
    times, T = paths[body]
    R, t = T[:, :3, :3], T[:, :3, 3]
    return {
        name: np.einsum("nji,nj->ni", R, _positions_at(path, times) - t)
        for name, path in paths.items()
    }


def _rig_view(found: _Found, rig: RigArtifact, paths: dict[str, TimedPoses]) -> RigOfManyView:
    """The rig of many cameras: its cameras and joints, their paths when written, a few
    instants to draw it at, and which cameras ran from images."""
    T_ref_cam = {
        c: se3.invert_transforms(r.T_cam_ref)
        for c, r in rig.cameras.items()
        if r.T_cam_ref is not None
    }
    joints = []
    for name, j in rig.joints.items():
        p = j.between[0]
        if any(b not in T_ref_cam for b in j.between):
            continue  # a body seen only in another recording: not drawn at that instant
        point = se3.transform_points(T_ref_cam[p], j.position_in[p]) if j.model.has_point else None
        joints.append((name, j.type, j.between[0], j.between[1], point))
    instants = np.zeros(0)
    bent: dict[str, np.ndarray] = {}
    at: dict[str, np.ndarray] = {}
    ref = paths.get(rig.reference_camera)
    if ref is not None and ref[0].size:
        n = ref[0].size
        idx = np.linspace(0, n - 1, min(n, RIG_INSTANTS)).round().astype(int)
        idx = np.union1d(idx, [min(rig.reference_frame, n - 1)])
        instants = ref[0][idx]
        bent = _in_body(paths, rig.reference_camera)
        at = {name: x[idx] for name, x in bent.items()}
    return RigOfManyView(
        rig.length_unit,
        rig.reference_camera,
        T_ref_cam,
        joints,
        bent,
        instants,
        at,
        [c for c in found.cameras if c in found.intrinsics or c in found.poses],
    )


def _rig_residuals(
    found: _Found, rig: RigArtifact
) -> tuple[list[F.ResidualSeries], dict[str, list[float]]]:
    """Each joint's residual per frame from ``joint_residuals.csv``: one series per joint,
    residual kind (its point, axis, rotation or translation rows) and recording; and the
    times of the frames each joint rejected.

    Raises
    ------
    InputError
        The file cannot be read.
    """
    got = read_joint_residuals(found.run_dir / RESIDUALS_FILE)
    several = len({r.recording for r in got}) > 1
    scale, shown = display_unit(rig.length_unit)
    series: list[F.ResidualSeries] = []
    rejected: dict[str, list[float]] = {}
    for r in got:
        j = rig.joints.get(r.joint)
        if j is None:
            continue  # a joint rig.yaml does not have: the file is older than it
        p, q = j.between
        rejected.setdefault(r.joint, []).extend(r.times[~r.used].tolist())
        what = {
            "pos": (f"the joint's point as {p} and as {q} carry it, |G_{p} o_{p} - G_{q} o_{q}|",
                    scale, shown),
            "rot": (f"the axis as {p} and as {q} carry it (rotation off the axis)"
                    if j.model.has_axis else
                    f"rotation, |log(R_{p}^T R_{q} R_{q}_{p})|", 1.0, "deg"),
            "trans": ("translation (at the midpoint between the two bodies)", scale, shown),
        }  # fmt: skip
        where = f", recording {r.recording}" if several else ""
        for kind in sorted(r.values, key=lambda k: k == "rot"):  # lengths first
            text, factor, unit = what[kind]
            series.append(
                F.ResidualSeries(
                    f"{r.joint} ({j.type}, {p}-{q}){where}: {text}",
                    r.times,
                    r.values[kind] * factor,
                    ~r.used,
                    unit,
                )
            )
    return series, rejected


def _angle_panel(
    joint: str,
    p: str,
    q: str,
    angles: HingeAngles | BallAngles,
    times: np.ndarray,
    rejected: np.ndarray,
    zero: float | None,
) -> F.AngleSeries:
    """One joint's angles over ``times`` as a panel of the angle figure: a hinge's angle
    about its axis, a ball's rotation vector (``q`` relative to ``p``)."""
    labels: tuple[str, ...]
    if isinstance(angles, HingeAngles):
        lo, hi = float(angles.angle_deg.min()), float(angles.angle_deg.max())
        title = (f"{joint} (hinge, {p}-{q}): {q} turning about the axis in {p} "
                 f"(right-hand rule), {lo:.1f} to {hi:.1f} deg")  # fmt: skip
        values, labels = angles.angle_deg[:, None], ("angle",)
    else:
        title = (f"{joint} (ball, {p}-{q}): {q}'s rotation relative to {p}, as a "
                 f"rotation vector in {p}'s frame")  # fmt: skip
        values, labels = angles.rotvec_deg, ("x", "y", "z")
    return F.AngleSeries(title, times, values, labels, rejected, zero)


def _rig_angles(
    rig: RigArtifact, paths: dict[str, TimedPoses], rejected: dict[str, list[float]]
) -> dict[str, F.AngleSeries]:
    """Each ball and hinge joint's angles over time, by joint (as ``acscal trajectory --rig``
    computes them, :func:`~acs_cli.stages.trajectory.rig_angles`, here from the run's
    trajectories), the frames it rejected marked."""
    cams = {c: paths[c] for c in rig.cameras if c in paths}
    return {
        s.joint: _angle_panel(
            s.joint,
            *rig.joints[s.joint].between,
            s.angles,
            s.times,
            listed_mask(s.times, rejected.get(s.joint)),
            None if s.zero is None else float(s.times[s.zero]),
        )
        for s in rig_angles(rig, cams)
    }


def _rig_estimates(found: _Found, rig: RigArtifact) -> list[Estimate]:
    """Every camera's pose and scale and every joint of ``rig.yaml``, with their std."""
    src = found.rel(rig.source)
    u = rig.length_unit
    rows: list[Estimate] = []
    for c, r in rig.cameras.items():
        if c == rig.reference_camera or r.T_cam_ref is None:
            continue
        for i, ax in enumerate("xyz"):
            rows.append(
                Estimate(f"{c} t_cam_ref {ax}", float(r.T_cam_ref[i, 3]),
                         float(r.translation_std[i]), u, src)
            )  # fmt: skip
        rows.append(
            Estimate(f"{c} rotation to {rig.reference_camera} (angle)",
                     float(se3.rotation_angle_deg(r.T_cam_ref[:3, :3][None])[0]),
                     float(np.linalg.norm(r.rotation_std_deg)), "deg", src)
        )  # fmt: skip
        if r.unknown_scale:
            rows.append(Estimate(f"{c} scale", r.scale, r.scale_std, f"{u} per unit", src))
    for name, j in rig.joints.items():
        for c, pos in j.position_in.items():
            std = j.position_std_in.get(c)
            for i, ax in enumerate("xyz"):
                rows.append(
                    Estimate(f"{name} ({j.type}) in {c} {ax}", float(pos[i]),
                             None if std is None else float(std[i]), u, src)
                )  # fmt: skip
        for c, axis in j.axis_in.items():
            rows.append(
                Estimate(f"{name} axis in {c} [" + " ".join(f"{v:+.4f}" for v in axis) + "]",
                         None, j.axis_std_deg_in.get(c), "deg", src)
            )  # fmt: skip
        rows.append(Estimate(f"{name} residual RMS", j.residual_rms, None, u, src, 4))
    for c, b in rig.bundle_adjustment.items():  # the rig's bundle adjustment on the corners
        _bundle_rows(rows, c, b, src)
    return rows


def _intrinsic(quantity: str, value: float, std: float | None, unit: str, src: str) -> Estimate:
    """An intrinsic parameter's row: a std of exactly 0 is a parameter held fixed (the
    artifacts record held parameters so: pinhole ``k3``, rational ``k4 k5 k6`` in a bundle
    adjustment), shown as "fixed"."""
    fixed = std is not None and std == 0.0
    return Estimate(quantity, value, None if fixed else std, unit, src, fixed=fixed)


def _bundle_rows(rows: list[Estimate], who: str, sec: BundleSection, src: str) -> None:
    """The intrinsics and RMS of one camera's bundle adjustment."""
    for key, val in sec.values().items():
        unit = "px" if key in ("fx", "fy", "cx", "cy") else ""
        rows.append(
            _intrinsic(
                f"{who} {key} (bundle adjustment)", val, sec.intrinsics_std.get(key), unit, src
            )
        )
    rows.append(
        Estimate(f"{who} reprojection RMS (bundle adjustment)", sec.rms_px, None, "px", src, 4)
    )


def _poses_of(found: _Found, cam: str) -> list[tuple[Path, PosesArtifact]]:
    """The readable poses NPZs of camera ``cam`` (each read once; see :meth:`_Found.load`)."""
    out = []
    for p in found.poses.get(cam, []):
        try:
            out.append((p, found.load(p)))
        except AcsError:
            continue
    return out


def _resolve_input(
    found: _Found, art: JointArtifact | RelposeArtifact, role: str, cam: str
) -> Path:
    """An input file an artifact records, found again (the run folder may have moved)."""
    artifact = Path(str(art.source))
    rec = art.inputs.get(role)
    if not isinstance(rec, dict) or not isinstance(rec.get("path"), str):
        raise InputError(f"records no input '{role}'", path=artifact)
    recorded = Path(rec["path"])
    candidates = [recorded] if recorded.is_absolute() else []
    candidates += [
        found.run_dir / f"cam_{cam}" / recorded.name,
        artifact.parent / recorded,
        artifact.parent / recorded.name,
        recorded,
    ]
    for c in candidates:
        if c.is_file():
            if rec.get("sha256") and rec["sha256"] != found.load(c).sha256:
                found.warn(
                    "report",
                    f"{_rel(c, found.run_dir)} changed since {artifact.name} was made from it",
                )
            return c
    raise InputError(f"cannot find its input {role} (recorded as {recorded})", path=artifact)


def _pair_as_recorded(found: _Found, art: JointArtifact | RelposeArtifact) -> PairedTrajectories:
    a = found.trajectory(_resolve_input(found, art, "poses_a", "a"))
    b = found.trajectory(_resolve_input(found, art, "poses_b", "b"))
    pairing = art.quality.pairing
    by = "auto" if pairing is None else pairing.pair_by
    max_dt = None if pairing is None else pairing.max_dt_s
    return pair_loaded(a, b, by, max_dt)


def _views(found: _Found) -> tuple[F.CameraView, F.CameraView]:
    out = []
    for cam in CAMERAS:
        intr = found.intrinsics.get(cam)
        out.append(
            F.CameraView() if intr is None else F.CameraView(intr.image_size, intr.camera_matrix)
        )
    return out[0], out[1]


# --------------------------------------------------------------------------- sections


def _trajectory(found: _Found) -> tuple[F.AngleSeries, RigTrajectory]:
    """The rig's trajectory (from relpose.yaml, else from an overlap joint.yaml) and its
    joint's angles over time (as ``acscal trajectory`` writes them to ``angles.csv``)."""
    if found.relpose is not None:
        pair = _pair_as_recorded(found, found.relpose)
        rec = recover_from_relpose(found.relpose, pair)
        t = rec.trajectory
        x = pair.a.timestamps
        a = pair_angles(rec, found.relpose, DEFAULT_EULER)
        angles = _angle_panel("the joint", "A", "B", a, x, rec.rejected, float(x[t.reference]))
        return angles, RigTrajectory(
            "relpose.yaml: the joint from A and from B in camera A's reference frame",
            rec.length_unit,
            t.T_r_a,
            t.T_r_b,
            t.joint_from_a,
            t.joint_from_b,
            t.consistency,
            pair.a.timestamps,
            rec.rejected,
            t.reference,
            rec.position_in_a,
            agree_at_reference=_exact(t.consistency[t.reference], rec.position_in_a),
        )
    joint = found.joint
    if joint is not None and joint.scenario == "overlap":
        o_a, o_b = joint.joint.position_in_a, joint.joint.position_in_b
        if o_b is None:
            raise InputError("joint.position_in_a/b must be three numbers each", path=joint.source)
        pair = _pair_as_recorded(found, joint)
        Ta, Tb = pair.a.T_world_cam, pair.b.T_world_cam
        t = recover_trajectory(Ta, Tb, overlap_relative_pose(Ta, Tb, 0), o_a, o_b, 0)
        frames = joint.quality.frames.get("ab")
        x, rejected = pair.a.timestamps, _rejected(frames, pair.a.timestamps)
        D = articulation_from_orientations(t.T_r_a[:, :3, :3], t.T_r_b[:, :3, :3], 0)
        ball = ball_angles(D, float("nan"), 0, DEFAULT_EULER)
        angles = _angle_panel("the joint", "A", "B", ball, x, rejected, float(x[0]))
        return angles, RigTrajectory(
            "joint.yaml (overlap): the joint from A and from B in camera A's frame at frame 0",
            joint.joint.units or "m",
            t.T_r_a,
            t.T_r_b,
            t.joint_from_a,
            t.joint_from_b,
            t.consistency,
            pair.a.timestamps,
            _rejected(frames, pair.a.timestamps),
            0,
            o_a,
        )
    raise InputError(
        "no relpose.yaml (and no overlap joint.yaml): the rig's trajectory needs the "
        "relative pose of the cameras"
    )


def _exact(distance: float, joint: np.ndarray) -> bool:
    """Whether ``distance`` is zero to rounding (a value zero by construction, e.g. the joint
    seen from A and from B at a reference instant whose pose the joint corrected)."""
    return bool(distance <= 1e-9 * max(float(np.linalg.norm(joint)), 1.0))


def _rejected(frames: FramesUsed | None, labels: np.ndarray) -> np.ndarray:
    return np.zeros(labels.shape[0], dtype=bool) if frames is None else frames.mask(labels)


def _joint_series(found: _Found, joint: JointArtifact) -> list[F.ResidualSeries]:
    """Residuals of the joint stage: per camera (fixed joint) or per pair (overlap)."""
    scale, shown = display_unit(joint.joint.units or "m")
    series = []
    if joint.scenario == "overlap":
        pair = _pair_as_recorded(found, joint)
        o_a, o_b = joint.joint.position_in_a, joint.joint.position_in_b
        if o_b is None:
            raise InputError("joint.position_in_a/b must be three numbers each", path=joint.source)
        r = overlap_residuals(pair.a.T_world_cam, pair.b.T_world_cam, o_a, o_b)
        series.append(
            F.ResidualSeries(
                "joint.yaml (overlap, Algorithm I): |T_w_a o_a - T_w_b o_b| per paired frame",
                pair.a.timestamps,
                r * scale,
                _rejected(joint.quality.frames.get("ab"), pair.a.timestamps),
                shown,
            )
        )
        return series
    for cam in CAMERAS:
        o = joint.joint.position(cam)
        w = joint.quality.joint_in_world.get(cam)
        if o is None or w is None:
            continue
        traj = found.trajectory(_resolve_input(found, joint, f"poses_{cam}", cam))
        r = fixed_joint_residuals(traj.T_world_cam, o, w)
        series.append(
            F.ResidualSeries(
                f"joint.yaml (fixed joint, Algorithm II), camera {cam.upper()}: "
                f"|T_w_{cam} o_{cam} - joint in world| per frame",
                traj.timestamps,
                r * scale,
                _rejected(joint.quality.frames.get(cam), traj.timestamps),
                shown,
            )
        )
    return series


def _reprojection(found: _Found) -> list[F.ReprojectionData]:
    data = []
    for cam in found.cameras:
        if cam not in found.intrinsics and cam not in found.poses:
            continue
        names: list[str] = []
        rms = np.zeros(0)
        overall = None
        intr = found.intrinsics.get(cam)
        if intr is not None:
            names = list(intr.per_view_rms_px)
            rms = np.asarray(list(intr.per_view_rms_px.values()), dtype=float)
            overall = intr.rms_px
        arts = [(p.name, art) for p, art in _poses_of(found, cam) if art.reprojection_rms.size]
        poses = {k: art.reprojection_rms for k, art in arts}
        images = {k: list(art.trajectory.names) for k, art in arts if art.trajectory.names}
        data.append(
            F.ReprojectionData(cam, names, rms, overall, poses, images, found.colors.get(cam))
        )
    return data


def _corner_errors(found: _Found) -> list[F.CornerErrorData]:
    """Every posed corner's reprojection error per camera, recomputed from its poses NPZs
    (corners, board points, board poses) and the camera's ``intrinsics.yaml``."""
    data = []
    for cam in found.cameras:
        intr = found.intrinsics.get(cam)
        if intr is None:
            continue
        observed, residual = [], []
        for _, art in _poses_of(found, cam):
            if art.corners is None or art.board_points is None or art.metric_scale is False:
                continue
            got = corner_residuals(
                art.corners,
                art.board_points,
                art.trajectory.T_world_cam,
                intr.model,
                intr.camera_matrix,
                intr.distortion,
            )
            observed.append(got.observed)
            residual.append(got.residual)
        if observed:
            data.append(
                F.CornerErrorData(
                    cam,
                    np.vstack(observed),
                    np.vstack(residual),
                    intr.principal_point,
                    found.colors.get(cam),
                )
            )
    return data


def _coverage(found: _Found) -> list[F.CoverageData]:
    data = []
    for cam in found.cameras:
        chunks = [
            art.corners.reshape(-1, 2)
            for _, art in _poses_of(found, cam)
            if art.corners is not None
        ]
        if not chunks:
            continue
        corners = np.vstack(chunks)
        corners = corners[np.isfinite(corners).all(axis=1)]  # NaN: a target's unseen corner
        if not corners.size:
            continue
        intr = found.intrinsics.get(cam)
        if intr is not None:
            size = intr.image_size
        else:
            hi = np.ceil(corners.max(axis=0))
            size = (int(hi[0]) + 1, int(hi[1]) + 1)
        data.append(F.CoverageData(cam, corners, size))
    return data


# --------------------------------------------------------------------------- tables


def _vec_rows(
    rows: list[Estimate],
    label: str,
    values: np.ndarray | None,
    stds: np.ndarray | None,
    unit: str,
    source: str,
    axes: Sequence[str],
) -> None:
    """One row per coordinate of ``values`` (named by ``axes``)."""
    if values is None:
        return
    v = np.atleast_1d(np.asarray(values, dtype=float))
    s = None if stds is None else np.atleast_1d(np.asarray(stds, dtype=float))
    for i, name in enumerate(list(axes)[: v.size]):
        std = None if s is None or i >= s.size else float(s[i])
        rows.append(Estimate(f"{label} {name}", float(v[i]), std, unit, source))


def _estimates(found: _Found) -> list[Estimate]:
    """Every estimated quantity with its std and unit."""
    rows: list[Estimate] = []
    for cam in found.cameras:
        intr = found.intrinsics.get(cam)
        if intr is None:
            continue
        src = found.rel(intr.source)
        K = intr.camera_matrix
        std: dict[str, Any] = intr.std or {}
        C = F.camera_name(cam)
        for key, val in (("fx", K[0, 0]), ("fy", K[1, 1]), ("cx", K[0, 2]), ("cy", K[1, 2])):
            rows.append(_intrinsic(f"camera {C} {key}", float(val), std.get(key), "px", src))
        dstd = std.get("distortion") or []
        names = intr.distortion_names or [f"d{i}" for i in range(intr.distortion.size)]
        for i, (name, val) in enumerate(zip(names, intr.distortion, strict=False)):
            s = float(dstd[i]) if i < len(dstd) else None
            rows.append(_intrinsic(f"camera {C} {name}", float(val), s, "", src))
        rows.append(Estimate(f"camera {C} reprojection RMS", intr.rms_px, None, "px", src, 4))
    if found.joint is not None:
        art = found.joint
        src = found.rel(art.source)
        unit = art.joint.units or "m"
        for cam in CAMERAS:
            _vec_rows(
                rows,
                f"joint in {cam.upper()} (o_{cam})",
                art.joint.position(cam),
                art.joint.std(cam),
                unit,
                src,
                "xyz",
            )
        for cam, sec in art.quality.bundle_adjustment.items():
            _bundle_rows(rows, f"camera {cam.upper()}", sec, src)
        for key, noise in art.quality.estimated_pose_noise.items():
            rows.append(
                Estimate(f"pose noise ({key}): translation", noise.sigma_trans, None, unit, src, 3)
            )
            rows.append(
                Estimate(f"pose noise ({key}): rotation", noise.sigma_rot_deg, None, "deg", src, 3)
            )
    if found.relpose is not None:
        rp = found.relpose
        src = found.rel(rp.source)
        rel = rp.relative_pose
        unit_b = "B units" if rp.unknown_scale else rp.length_unit
        unit_a = "A units" if rp.unknown_scale else unit_b
        _vec_rows(rows, "R_a_b", rel.rpy_deg, rel.rpy_deg_std, "deg", src, ["roll", "pitch", "yaw"])
        _vec_rows(
            rows,
            "B's origin in A (t_a_b)",
            rel.translation_b_in_a,
            rel.translation_b_in_a_std,
            unit_b,
            src,
            "xyz",
        )
        if rp.joint is not None:
            j = rp.joint
            _vec_rows(
                rows, "joint in A (o_a, relpose)", j.position_in_a, j.position_in_a_std,
                unit_a, src, "xyz",
            )  # fmt: skip
            _vec_rows(
                rows, "joint in B (o_b, relpose)", j.position_in_b, j.position_in_b_std,
                unit_b, src, "xyz",
            )  # fmt: skip
        sc = rp.scale
        if sc is not None:
            rows.append(
                Estimate(
                    "phi_ba = mu_b / mu_a", sc.phi_ba, sc.phi_ba_std, "B units per A unit", src
                )
            )
            for key, val, s in (("mu_a", sc.mu_a, sc.mu_a_std), ("mu_b", sc.mu_b, sc.mu_b_std)):
                if val is not None:
                    rows.append(Estimate(key, val, s, f"{key[-1].upper()} units per metre", src))
        for cam, sec in rp.quality.bundle_adjustment.items():
            _bundle_rows(rows, f"camera {cam.upper()}", sec, src)
        rp_noise = rp.quality.estimated_pose_noise
        if rp_noise is not None:
            rows.append(
                Estimate("pose noise: translation", rp_noise.sigma_trans, None, unit_b, src, 3)
            )
            rows.append(
                Estimate("pose noise: rotation", rp_noise.sigma_rot_deg, None, "deg", src, 3)
            )
    return rows


def _collect_warnings(found: _Found) -> None:
    for cam in found.cameras:
        intr = found.intrinsics.get(cam)
        if intr is not None:
            src = found.rel(intr.source)
            for w in intr.warnings:
                found.warn(src, w)
            dropped = [] if intr.images is None else intr.images.dropped_outliers
            if dropped:
                shown = ", ".join(str({"image": d.image, "rms_px": d.rms_px}) for d in dropped)
                found.warn(src, f"{len(dropped)} view(s) dropped as outliers: {shown}")
        for p, art in _poses_of(found, cam):
            src = found.rel(p)
            for w in art.warnings:
                found.warn(src, w)
            skipped = art.skipped_images
            if skipped:
                found.warn(
                    src,
                    f"no board pose in {len(skipped)} image(s) (of {len(art) + len(skipped)}): "
                    f"{', '.join(skipped)}",
                )
    if found.rig is not None:
        for w in found.rig.warnings:
            found.warn(found.rel(found.rig.source), w)
    for a in (found.joint, found.relpose):
        if a is None:
            continue
        src = found.rel(a.source)
        for w in a.warnings:
            found.warn(src, w)
        pairing = a.quality.pairing
        said = any(src == s and "no partner" in t for s, t in found.warnings)
        if pairing is not None and (pairing.unpaired_a or pairing.unpaired_b) and not said:
            text = (
                f"unpaired samples: {pairing.unpaired_a} of A, {pairing.unpaired_b} "
                f"of B ({pairing.pairs} pairs, by {pairing.by})"
            )
            found.warn(src, text)


# --------------------------------------------------------------------------- verdict


def _coverage_fractions(found: _Found, coverage: Sequence[F.CoverageData]) -> dict[str, float]:
    """Each camera's image coverage; one under half is a warning."""
    out = {}
    for c in coverage:
        frac = F.coverage_fraction(c.corners, c.image_size)
        out[c.camera] = frac
        if V.classify("coverage", frac) != "pass":
            found.warn(
                "report",
                f"camera {F.camera_name(c.camera)}: the detected corners cover "
                f"{V.THRESHOLDS['coverage'].show(frac)} of the image cells (under half): the "
                "distortion outside them is extrapolated; add views with the board near the "
                "image's borders and corners",
            )
    return out


def _warning_check(found: _Found, *sources: str) -> V.Check:
    """The check of the number of warnings listed from ``sources``."""
    return V.Check("warnings", float(sum(src in sources for src, _ in found.warnings)))


def _level(verdict: VerdictSection | None) -> str | None:
    """An artifact's ``verdict.level`` (None for one written before verdicts)."""
    return None if verdict is None else verdict.level


def _norm(v: np.ndarray | None) -> float:
    """The length of ``v`` (0 for None: no distance, no check)."""
    return 0.0 if v is None else float(np.linalg.norm(v))


def _noise(n: PoseNoise | None) -> tuple[float, float] | None:
    """``(sigma_trans, sigma_rot_deg)`` of an estimated pose noise, if any."""
    return None if n is None else (n.sigma_trans, n.sigma_rot_deg)


def _bundle_verdicts(
    file: str, src: str, bundles: dict[str, BundleSection]
) -> list[V.StageVerdict]:
    """One verdict (its reprojection RMS) per camera an artifact bundle-adjusted."""
    return [
        V.StageVerdict(
            f"bundle adjustment ({file}), camera {F.camera_name(cam)}",
            src,
            V.reprojection_checks(sec.rms_px),
        )
        for cam, sec in bundles.items()
    ]


def _joint_std_checks(joint: JointSection) -> list[V.Check]:
    """The std-against-distance check of a joint section, per camera: its largest std (the
    verdict's measure, :func:`acs_cli.core.quality.largest_std`) over its distance."""
    checks = []
    for cam in CAMERAS:
        o, cov = joint.position(cam), joint.covariance(cam)
        if o is not None and cov is not None:
            checks += V.joint_checks(
                None, _norm(o), [largest_std(cov)], subject=f"joint in {cam.upper()}"
            )
    return checks


def _verdicts(found: _Found, coverage: dict[str, float]) -> list[V.StageVerdict]:
    """Each stage's verdict, in the run's order (call after the warnings are collected)."""
    out: list[V.StageVerdict] = []
    for cam in found.cameras:
        intr = found.intrinsics.get(cam)
        if intr is not None:
            src = found.rel(intr.source)
            checks = V.reprojection_checks(intr.rms_px, coverage.get(cam))
            checks += V.artifact_verdict_check(_level(intr.verdict))
            out.append(
                V.StageVerdict(
                    f"intrinsics, camera {F.camera_name(cam)}",
                    src,
                    [*checks, _warning_check(found, src)],
                )
            )
    for cam in found.cameras:
        arts = _poses_of(found, cam)
        if not arts:
            continue
        srcs = [found.rel(p) for p, _ in arts]
        rms = np.concatenate([a.reprojection_rms for _, a in arts])
        checks = V.reprojection_checks(
            float(np.sqrt(np.mean(rms**2))) if rms.size else None,
            None if cam in found.intrinsics else coverage.get(cam),
        )
        out.append(
            V.StageVerdict(
                f"poses, camera {F.camera_name(cam)}",
                ", ".join(srcs),
                [*checks, _warning_check(found, *srcs)],
            )
        )
    joint = found.joint
    if joint is not None:
        src = found.rel(joint.source)
        q = joint.quality
        keys = [("ab", "a", 2)] if joint.scenario == "overlap" else [("a", "a", 1), ("b", "b", 1)]
        checks = []
        for key, cam, n in keys:
            res = q.residual_rms.get(key) if isinstance(q.residual_rms, dict) else q.residual_rms
            checks += V.joint_checks(
                res,
                _norm(joint.joint.position(cam)),
                None,
                _noise(q.estimated_pose_noise.get(key)),
                n,
                "residual" if key == "ab" else f"camera {cam.upper()}",
            )
        checks += _joint_std_checks(joint.joint)
        checks += V.artifact_verdict_check(_level(joint.verdict))
        out.append(V.StageVerdict("joint", src, [*checks, _warning_check(found, src)]))
        out += _bundle_verdicts("joint.yaml", src, q.bundle_adjustment)
    rp = found.relpose
    if rp is not None:
        src = found.rel(rp.source)
        checks = []
        if rp.joint is not None:
            checks += V.joint_checks(
                rp.quality.residual_rms,
                _norm(rp.joint.position_in_b),
                None,
                _noise(rp.quality.estimated_pose_noise),
                2,
                "joint from A and from B",
            )
            checks += _joint_std_checks(rp.joint)
        checks += V.artifact_verdict_check(_level(rp.verdict))
        out.append(V.StageVerdict("relpose", src, [*checks, _warning_check(found, src)]))
        out += _bundle_verdicts("relpose.yaml", src, rp.quality.bundle_adjustment)
    rig = found.rig
    if rig is not None:
        src = found.rel(rig.source)
        checks = []
        for name, j in rig.joints.items():
            o = j.position_in.get(j.between[0])
            if o is not None:
                checks += V.joint_checks(
                    j.residual_rms, _norm(o), j.position_std_in.get(j.between[0]), subject=name
                )
        checks += V.artifact_verdict_check(_level(rig.verdict))
        out.append(V.StageVerdict("rig", src, [*checks, _warning_check(found, src)]))
        out += _bundle_verdicts("rig.yaml", src, rig.bundle_adjustment)
    return out


def _intrinsics_text(K: np.ndarray, rms: float | None) -> str:
    """``fx fy cx cy`` of ``K`` and the RMS, for the final-results table."""
    text = f"fx {K[0, 0]:.2f}, fy {K[1, 1]:.2f}, cx {K[0, 2]:.2f}, cy {K[1, 2]:.2f} px"
    return text if rms is None else f"{text}; reprojection RMS {rms:.3g} px"


def _finals(found: _Found) -> tuple[list[FinalChoice], list[str]]:
    """Where the final intrinsics and joint are, and what the run folder exported."""
    finals: list[FinalChoice] = []
    adjusted: set[str] = set()
    # the last stage's bundle adjustment is final: relpose, then joint; a rig's on its own
    bundles = [
        (found.rel(a.source), "quality.bundle_adjustment", a.quality.bundle_adjustment)
        for a in (found.relpose, found.joint)
        if a is not None
    ]
    if found.rig is not None:
        rig = found.rig
        bundles.append((found.rel(rig.source), "bundle_adjustment", rig.bundle_adjustment))
    bundled: set[str] = set()
    for cam in found.cameras:
        C = F.camera_name(cam)
        body = cam.rsplit("/", 1)[-1]  # a rig's bundle is per body, across its recordings
        for src, key, secs in bundles:
            sec = secs.get(body)
            if sec is not None and body in bundled:  # listed with another recording's label
                adjusted.add(cam)
                break
            if sec is not None:
                bundled.add(body)
                finals.append(
                    FinalChoice(
                        f"intrinsics of camera {C}",
                        f"{src}: {key}.{body}",
                        f"bundle-adjusted from {sec.intrinsics_file} on {sec.frames} frames: "
                        + _intrinsics_text(sec.camera_matrix, sec.rms_px),
                    )
                )
                adjusted.add(cam)
                break
        else:
            intr = found.intrinsics.get(cam)
            if intr is not None:
                finals.append(
                    FinalChoice(
                        f"intrinsics of camera {C}",
                        found.rel(intr.source),
                        "the calibration (no bundle adjustment refined it): "
                        + _intrinsics_text(intr.camera_matrix, intr.rms_px),
                    )
                )
    if found.relpose is not None and found.relpose.joint is not None:
        j = found.relpose.joint
        how = j.source or "the joint relpose.yaml used"
        if found.relpose.quality.bundle_adjustment:
            how += "; bundle-adjusted with the relative pose"
        finals.append(FinalChoice("joint", f"{found.rel(found.relpose.source)}: joint", how))
    elif found.joint is not None:
        how = "bundle-adjusted" if found.joint.quality.bundle_adjustment else "pose-based"
        finals.append(
            FinalChoice(
                "joint",
                f"{found.rel(found.joint.source)}: joint",
                f"{how} ({found.joint.scenario.replace('_', ' ')})",
            )
        )
    if found.rig is not None:
        how = "bundle-adjusted" if found.rig.bundle_adjustment else "pose-based solve"
        finals.append(
            FinalChoice("rig (camera poses and joints)", found.rel(found.rig.source), how)
        )
    exported = []
    for cam in found.cameras:
        intr = found.intrinsics.get(cam)
        if intr is None:
            continue
        for kind, name in intr.exports.items():
            path = Path(str(intr.source)).parent / name
            text = f"{found.rel(path)} ({kind}): the intrinsics of {found.rel(intr.source)}"
            if cam in adjusted:
                text += ", not the final bundle-adjusted ones"
            exported.append(text if path.is_file() else f"{text} (file missing)")
    return finals, exported


# --------------------------------------------------------------------------- the report


def _artifact_rows(found: _Found) -> list[ArtifactRow]:
    rows = []
    items: list[IntrinsicsArtifact | JointArtifact | RelposeArtifact] = [
        found.intrinsics[c] for c in found.cameras if c in found.intrinsics
    ]
    items += [a for a in (found.joint, found.relpose) if a is not None]
    if found.rig is not None:
        h = found.rig.header
        rows.append(
            ArtifactRow(found.rel(found.rig.source), str(h.get("schema")),
                        str(h.get("created")), str(h.get("method", "")))
        )  # fmt: skip
    for art in items:
        h = art.header
        rows.append(
            ArtifactRow(
                found.rel(art.source),
                str(h.get("schema")),
                str(h.get("created")),
                str(h.get("method", "")),
            )
        )
    for cam in found.cameras:
        for p in found.poses.get(cam, []):
            try:
                got = found.load(p)
            except AcsError as exc:
                found.notes.append(f"{found.rel(p)} could not be read: {exc}")
                got = None
            h = got.header if got is not None else {}
            rows.append(
                ArtifactRow(
                    found.rel(p),
                    str(h.get("schema", "acscal/poses")),
                    str(h.get("created", "")),
                    str(h.get("method", "")),
                )
            )
    return rows


def build_report(run_dir: Path, extra_warnings: Sequence[str] = ()) -> ReportModel:
    """Read a run folder into a :class:`ReportModel` (each file read once; nothing drawn).

    Parameters
    ----------
    run_dir : Path
        A run folder (``acscal run``'s output, or the same layout made by hand).
    extra_warnings : sequence of str
        Warnings to list besides the artifacts' own (source ``run``).

    Returns
    -------
    ReportModel

    Raises
    ------
    InputError
        ``run_dir`` is not a folder or holds no acscal artifact.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError("no such run folder", path=run_dir)
    found = _gather(run_dir)
    if not found.any_file:
        raise InputError(
            "holds no acscal artifact (expected cam_a/intrinsics.yaml, cam_a/poses.npz, "
            "joint.yaml, relpose.yaml or rig.yaml, as `acscal run` writes)",
            path=run_dir,
        )
    return _model(found, extra_warnings)


def _model(found: _Found, extra_warnings: Sequence[str]) -> ReportModel:
    created = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    run_dir = found.run_dir
    model = ReportModel(
        f"acscal calibration report: {run_dir.resolve().name}",
        f"acscal {acs_cli.__version__}, {created}, run folder {run_dir}",
        views=_views(found),
    )
    model.artifacts = _artifact_rows(found)
    model.artifact_notes = list(found.notes)
    model.notes = list(found.notes)

    rig = found.rig
    # why a section of the two-camera path is empty; a rig's report leaves those sections
    # out (a rig has its own, :func:`_rig_sections`)
    pair_skip = model.skip if rig is None else _no_note
    try:
        pair_angle, model.trajectory = _trajectory(found)
        if rig is None:
            model.angles = [pair_angle]
    except AcsError as exc:
        pair_skip("trajectory", f"Trajectory skipped: {exc.one_line()}")

    if found.joint is not None:
        try:
            model.residuals += _joint_series(found, found.joint)
        except AcsError as exc:
            model.skip("residuals", f"joint.yaml residuals skipped: {exc.one_line()}")
    else:
        pair_skip("residuals", "No joint.yaml: no residuals of the joint stage.")
    traj = model.trajectory
    if traj is not None and found.relpose is not None:
        scale, shown = display_unit(traj.unit)
        model.residuals.append(
            F.ResidualSeries(
                "relpose.yaml (Algorithm III/IV): |joint from A - joint from B| in the "
                "recovered trajectory",
                traj.x,
                traj.consistency * scale,
                traj.rejected,
                shown,
            )
        )
    elif found.relpose is None:
        pair_skip("residuals", "No relpose.yaml: no residuals of the relative-pose stage.")
    if rig is not None:
        _rig_sections(found, rig, model)

    model.reprojection = _reprojection(found)
    if not model.reprojection and not found.intrinsics and not found.poses:
        pair_skip("reprojection", "No intrinsics.yaml and no poses: no reprojection errors.")

    model.corner_errors = _corner_errors(found)
    if not model.corner_errors:
        pair_skip(
            "corners",
            "No per-corner errors: they need a camera's intrinsics.yaml and poses with corners.",
        )

    model.coverage = _coverage(found)
    coverage = _coverage_fractions(found, model.coverage)
    if not model.coverage:
        pair_skip(
            "coverage",
            "No poses with corners (cam_<x>/*.npz from acscal poses): no coverage figure.",
        )

    model.estimates = _estimates(found)
    if rig is not None:
        model.estimates += _rig_estimates(found, rig)
    if not model.estimates:
        model.skip("estimates", "No estimates: no intrinsics, joint or relpose artifact.")

    for w in extra_warnings:
        found.warn("run", w)
    _collect_warnings(found)
    model.verdicts = _verdicts(found, coverage)
    model.finals, model.exported = _finals(found)
    model.warnings = [f"{src}: {text}" for src, text in found.warnings]
    model.notes += [n for n in found.notes if n not in model.notes]
    return model


def _no_note(section: str, text: str) -> None:
    """A section note nobody shows (see ``pair_skip`` in :func:`_model`)."""


def _rig_sections(found: _Found, rig: RigArtifact, model: ReportModel) -> None:
    """A rig's view over time, each joint's residual per frame and its angles."""
    paths = _rig_paths(found, rig)
    model.rig = _rig_view(found, rig, paths)
    rejected: dict[str, list[float]] = {}
    if (found.run_dir / RESIDUALS_FILE).is_file():
        try:
            series, rejected = _rig_residuals(found, rig)
            model.residuals += series
        except AcsError as exc:
            model.skip("residuals", f"{RESIDUALS_FILE} could not be read: {exc.one_line()}")
    else:
        model.skip(
            "residuals",
            f"No {RESIDUALS_FILE} beside rig.yaml (a rig run of an earlier acscal): no "
            "residuals per frame; run acscal run again to write it.",
        )
    angles = _rig_angles(rig, paths, rejected)
    model.angles = list(angles.values())
    missing = [n for n, j in rig.joints.items() if j.model.has_point and n not in angles]
    if missing and not paths:
        model.skip(
            "angles",
            f"No {RIG_TRAJECTORIES}/ beside rig.yaml: no joint angles, and the rig is drawn "
            "at the reference instant only.",
        )
    elif missing:
        model.skip(
            "angles",
            f"No angles of {', '.join(missing)}: {RIG_TRAJECTORIES}/ has no path of both "
            "bodies of each (it holds the reference recording's instants; a body seen only "
            "in another recording has none).",
        )


def _check_html_output(output: Path) -> None:
    """Refuse to replace anything but an HTML file (an earlier report): ``-o`` naming a
    run's NPZ, YAML or cache by mistake must not turn it into HTML.

    Raises
    ------
    InputError
        ``output`` exists and is not an HTML file (or cannot be read to tell).
    """
    check_writable(output)  # a folder, a device, a symlink loop: named there
    target = resolve_output(output)
    if not target.exists():
        return
    try:
        with open(target, "rb") as fh:
            head = fh.read(512)
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or exc})", path=output) from exc
    start = head.lstrip(b"\xef\xbb\xbf \t\r\n").lower()
    if not (start.startswith(b"<!doctype html") or start.startswith(b"<html")):
        raise InputError(
            "exists and is not an HTML file (an earlier report); the report replaces only "
            "HTML: choose a new .html path",
            path=output,
        )


def run_report(run_dir: Path, output: Path, config: ReportConfig | None = None) -> ReportRun:
    """Write ``output`` (HTML) and its figures (``<name>_files/*.png``) for a run folder.

    The report is built first as a :class:`~acs_cli.report.model.ReportModel`
    (:func:`build_report`, every poses NPZ read once), then drawn
    (:func:`acs_cli.report.render.render_report`) and written.

    Parameters
    ----------
    run_dir : Path
        A run folder (``acscal run``'s output, or the same layout made by hand).
    output : Path
        The HTML file to write.
    config : ReportConfig, optional

    Returns
    -------
    ReportRun

    Raises
    ------
    InputError
        ``run_dir`` is not a folder or holds no acscal artifact; an output cannot be written.
    """
    cfg = config or ReportConfig()
    run_dir = Path(run_dir)
    output = Path(output)
    _check_html_output(output)
    model = build_report(run_dir, cfg.extra_warnings)
    inputs = [run_dir / f"cam_{c}" / "intrinsics.yaml" for c in CAMERAS]
    inputs += [run_dir / n for n in ("joint.yaml", "relpose.yaml", "rig.yaml", RESIDUALS_FILE)]
    check_distinct_output(output, [p for p in inputs if p.is_file()])
    rendered = render_report(model, cfg.dpi, cfg.max_frustums)

    fig_dir = figures_dir_for(output)
    written = []
    for key, name in FIGURE_NAMES.items():
        target = fig_dir / name
        if key in rendered.pngs:
            atomic_write_bytes(target, rendered.pngs[key])
            written.append(target)
        elif target.is_file():
            try:
                target.unlink()  # a figure of an earlier report that this one does not have
            except OSError:
                pass
    atomic_write_text(output, rendered.html)
    return ReportRun(output, fig_dir, written, list(model.notes), list(model.warnings))
