"""The report stage: ``acscal report RUN_DIR`` (and the end of ``acscal run``).

Reads what a run folder holds (``cam_<x>/intrinsics.yaml``, ``cam_<x>/*.npz`` poses,
``joint.yaml``, ``relpose.yaml``), draws the figures (:mod:`acs_cli.report.figures`) and
writes one self-contained HTML page (:mod:`acs_cli.report.html`) plus the same figures as
PNG files in ``<name>_files/`` beside it. A section whose artifact is missing or unreadable
is skipped with a note; a folder with no artifact at all is an :class:`InputError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

import acs_cli
from acs_cli.core.acs_trajectory import (
    fixed_joint_residuals,
    overlap_relative_pose,
    overlap_residuals,
    recover_trajectory,
)
from acs_cli.errors import AcsError, InputError
from acs_cli.io.artifacts import get_path, read_yaml_artifact, sha256_of
from acs_cli.io.atomic import atomic_write_bytes, atomic_write_text, check_distinct_output
from acs_cli.io.trajectory import (
    read_npz_header,
    read_npz_observations,
    read_npz_poses,
    read_npz_quality,
)
from acs_cli.report import figures as F
from acs_cli.report.html import Page
from acs_cli.stages.common import TIME_TOL, PairedTrajectories, load_pair, load_trajectory
from acs_cli.stages.trajectory import recover_from_relpose

__all__ = ["FIGURE_NAMES", "ReportConfig", "ReportRun", "figures_dir_for", "run_report"]

CAMERAS = ("a", "b")
#: The figures a report can hold, by key: file name in the figures folder.
FIGURE_NAMES = {
    "trajectory": "rig_trajectory.png",
    "reference": "rig_reference.png",
    "residuals": "joint_residuals.png",
    "reprojection": "reprojection.png",
    "coverage": "coverage.png",
}


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
    """The artifacts of a run folder (the readable ones) and the notes on the others."""

    run_dir: Path
    intrinsics: dict[str, tuple[Path, dict[str, Any]]] = field(default_factory=dict)
    poses: dict[str, list[Path]] = field(default_factory=dict)
    joint: tuple[Path, dict[str, Any]] | None = None
    relpose: tuple[Path, dict[str, Any]] | None = None
    notes: list[str] = field(default_factory=list)
    warnings: list[tuple[str, str]] = field(default_factory=list)
    any_file: bool = False

    def warn(self, source: str, text: str) -> None:
        if (source, text) not in self.warnings:
            self.warnings.append((source, text))


def _rel(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return str(path)


def _read_artifact(found: _Found, path: Path, kind: str) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    found.any_file = True
    try:
        return read_yaml_artifact(path, kind)
    except AcsError as exc:
        found.notes.append(f"{_rel(path, found.run_dir)} could not be read: {exc.one_line()}")
        return None


def _is_poses_npz(path: Path) -> bool:
    return path.suffix == ".npz" and not path.name.endswith(".detections.npz")


def _gather(run_dir: Path) -> _Found:
    found = _Found(run_dir)
    for cam in CAMERAS:
        d = run_dir / f"cam_{cam}"
        doc = _read_artifact(found, d / "intrinsics.yaml", "intrinsics")
        if doc is not None:
            found.intrinsics[cam] = (d / "intrinsics.yaml", doc)
        if d.is_dir():
            npzs = sorted(p for p in d.iterdir() if p.is_file() and _is_poses_npz(p))
            if npzs:
                found.any_file = True
                found.poses[cam] = npzs
    for name, kind in (("joint.yaml", "joint"), ("relpose.yaml", "relpose")):
        doc = _read_artifact(found, run_dir / name, kind)
        if doc is not None:
            setattr(found, kind, (run_dir / name, doc))
    return found


def _resolve_input(found: _Found, artifact: Path, doc: dict[str, Any], role: str, cam: str) -> Path:
    """An input file an artifact records, found again (the run folder may have moved)."""
    rec = get_path(doc, f"inputs.{role}", None)
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
            if rec.get("sha256") and rec["sha256"] != sha256_of(c):
                found.warn(
                    "report",
                    f"{_rel(c, found.run_dir)} changed since {artifact.name} was made from it",
                )
            return c
    raise InputError(f"cannot find its input {role} (recorded as {recorded})", path=artifact)


def _pair_as_recorded(found: _Found, artifact: Path, doc: dict[str, Any]) -> PairedTrajectories:
    pa = _resolve_input(found, artifact, doc, "poses_a", "a")
    pb = _resolve_input(found, artifact, doc, "poses_b", "b")
    rec = get_path(doc, "quality.pairing", {})
    by = rec.get("requested", "auto") if isinstance(rec, dict) else "auto"
    md = rec.get("max_dt_s") if isinstance(rec, dict) else None
    max_dt = float(md) if isinstance(md, (int, float)) and not isinstance(md, bool) else None
    return load_pair(
        pa, pb, "auto", "auto", by if by in ("auto", "timestamp", "index") else "auto", max_dt
    )


def _mask(labels: np.ndarray, listed: Any) -> np.ndarray:
    """Which of ``labels`` (timestamps) are in the list ``listed``."""
    mask = np.zeros(labels.shape[0], dtype=bool)
    if isinstance(listed, list):
        vals = np.asarray([v for v in listed if isinstance(v, (int, float))], dtype=float)
        if vals.size:
            mask = np.any(np.abs(labels[:, None] - vals[None, :]) <= TIME_TOL, axis=1)
    return mask


def _vec(value: Any, n: int = 3) -> np.ndarray | None:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    return arr if arr.shape == (n,) and np.all(np.isfinite(arr)) else None


def _display_unit(unit: str) -> tuple[float, str]:
    """Lengths in metres are shown in millimetres."""
    return (1000.0, "mm") if unit == "m" else (1.0, unit)


def _views(found: _Found) -> tuple[F.CameraView, F.CameraView]:
    out = []
    for cam in CAMERAS:
        view = F.CameraView()
        if cam in found.intrinsics:
            doc = found.intrinsics[cam][1]
            K = np.asarray(doc.get("camera_matrix", np.eye(3)), dtype=float)
            size = doc.get("image_size")
            if K.shape == (3, 3) and isinstance(size, list) and len(size) == 2:
                view = F.CameraView((int(size[0]), int(size[1])), K)
        out.append(view)
    return out[0], out[1]


# --------------------------------------------------------------------------- sections


@dataclass
class _Trajectory:
    title: str
    unit: str
    T_r_a: np.ndarray
    T_r_b: np.ndarray
    joint_a: np.ndarray
    joint_b: np.ndarray
    consistency: np.ndarray
    x: np.ndarray
    rejected: np.ndarray
    reference: int
    position_in_a: np.ndarray


def _trajectory(found: _Found) -> _Trajectory:
    """The rig's trajectory: from relpose.yaml, else from an overlap joint.yaml."""
    if found.relpose is not None:
        path, doc = found.relpose
        pair = _pair_as_recorded(found, path, doc)
        rec = recover_from_relpose(doc, path, pair)
        t = rec.trajectory
        return _Trajectory(
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
        )
    if found.joint is not None and found.joint[1].get("scenario") == "overlap":
        path, doc = found.joint
        o_a = _vec(get_path(doc, "joint.position_in_a", None))
        o_b = _vec(get_path(doc, "joint.position_in_b", None))
        if o_a is None or o_b is None:
            raise InputError("joint.position_in_a/b must be three numbers each", path=path)
        pair = _pair_as_recorded(found, path, doc)
        Ta, Tb = pair.a.T_world_cam, pair.b.T_world_cam
        t = recover_trajectory(Ta, Tb, overlap_relative_pose(Ta, Tb, 0), o_a, o_b, 0)
        unit = str(get_path(doc, "joint.units", "m"))
        return _Trajectory(
            "joint.yaml (overlap): the joint from A and from B in camera A's frame at frame 0",
            unit,
            t.T_r_a,
            t.T_r_b,
            t.joint_from_a,
            t.joint_from_b,
            t.consistency,
            pair.a.timestamps,
            _mask(pair.a.timestamps, get_path(doc, "quality.frames.ab.rejected", [])),
            0,
            o_a,
        )
    raise InputError(
        "no relpose.yaml (and no overlap joint.yaml): the rig's trajectory needs the "
        "relative pose of the cameras"
    )


def _joint_series(found: _Found, path: Path, doc: dict[str, Any]) -> list[F.ResidualSeries]:
    """Residuals of the joint stage: per camera (fixed joint) or per pair (overlap)."""
    unit = str(get_path(doc, "joint.units", "m"))
    scale, shown = _display_unit(unit)
    series = []
    if doc.get("scenario") == "overlap":
        pair = _pair_as_recorded(found, path, doc)
        o_a = _vec(get_path(doc, "joint.position_in_a", None))
        o_b = _vec(get_path(doc, "joint.position_in_b", None))
        if o_a is None or o_b is None:
            raise InputError("joint.position_in_a/b must be three numbers each", path=path)
        r = overlap_residuals(pair.a.T_world_cam, pair.b.T_world_cam, o_a, o_b)
        rej = _mask(pair.a.timestamps, get_path(doc, "quality.frames.ab.rejected", []))
        series.append(
            F.ResidualSeries(
                "joint.yaml (overlap, Algorithm I): |T_w_a o_a - T_w_b o_b| per paired frame",
                pair.a.timestamps,
                r * scale,
                rej,
                shown,
            )
        )
        return series
    for cam in CAMERAS:
        o = _vec(get_path(doc, f"joint.position_in_{cam}", None))
        w = _vec(get_path(doc, f"quality.joint_in_world.{cam}", None))
        if o is None or w is None:
            continue
        traj = load_trajectory(_resolve_input(found, path, doc, f"poses_{cam}", cam))
        r = fixed_joint_residuals(traj.T_world_cam, o, w)
        rej = _mask(traj.timestamps, get_path(doc, f"quality.frames.{cam}.rejected", []))
        series.append(
            F.ResidualSeries(
                f"joint.yaml (fixed joint, Algorithm II), camera {cam.upper()}: "
                f"|T_w_{cam} o_{cam} - joint in world| per frame",
                traj.timestamps,
                r * scale,
                rej,
                shown,
            )
        )
    return series


def _reprojection(found: _Found) -> list[F.ReprojectionData]:
    data = []
    for cam in CAMERAS:
        if cam not in found.intrinsics and cam not in found.poses:
            continue
        names: list[str] = []
        rms = np.zeros(0)
        overall = None
        if cam in found.intrinsics:
            doc = found.intrinsics[cam][1]
            per_view = doc.get("per_view_rms_px")
            if isinstance(per_view, dict):
                names = [str(k) for k in per_view]
                rms = np.asarray([float(v) for v in per_view.values()], dtype=float)
            if isinstance(doc.get("rms_px"), (int, float)):
                overall = float(doc["rms_px"])
        poses = {}
        for p in found.poses.get(cam, []):
            r = read_npz_quality(p)[0]
            if r.size:
                poses[p.name] = r
        data.append(F.ReprojectionData(cam, names, rms, overall, poses))
    return data


def _coverage(found: _Found) -> list[F.CoverageData]:
    data = []
    for cam in CAMERAS:
        chunks = []
        for p in found.poses.get(cam, []):
            obs = read_npz_observations(p)
            if obs is not None:
                chunks.append(obs.corners.reshape(-1, 2))
        if not chunks:
            continue
        corners = np.vstack(chunks)
        size: tuple[int, int] | None = None
        if cam in found.intrinsics:
            s = found.intrinsics[cam][1].get("image_size")
            if isinstance(s, list) and len(s) == 2:
                size = (int(s[0]), int(s[1]))
        if size is None:
            hi = np.ceil(corners.max(axis=0))
            size = (int(hi[0]) + 1, int(hi[1]) + 1)
        data.append(F.CoverageData(cam, corners, size))
    return data


# --------------------------------------------------------------------------- tables


def _g(x: Any, digits: int = 6) -> str:
    if x is None:
        return "—"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    return f"{v:.{digits}g}"


def _estimates(found: _Found) -> list[list[str]]:
    """Rows ``quantity, value, std, unit, source`` of every estimated quantity."""
    rows: list[list[str]] = []

    def vec_rows(
        label: str, values: Any, stds: Any, unit: str, source: str, axes: Sequence[str]
    ) -> None:
        v = np.atleast_1d(np.asarray(values if values is not None else [], dtype=float))
        s = None if stds is None else np.atleast_1d(np.asarray(stds, dtype=float))
        for i, name in enumerate(list(axes)[: v.size]):
            std = "—" if s is None or i >= s.size else _g(s[i], 3)
            rows.append([f"{label} {name}", _g(v[i]), std, unit, source])

    for cam in CAMERAS:
        if cam not in found.intrinsics:
            continue
        path, doc = found.intrinsics[cam]
        src = _rel(path, found.run_dir)
        K = np.asarray(doc.get("camera_matrix", np.full((3, 3), np.nan)), dtype=float)
        std: dict[str, Any] = doc["std"] if isinstance(doc.get("std"), dict) else {}
        for key, val in (("fx", K[0, 0]), ("fy", K[1, 1]), ("cx", K[0, 2]), ("cy", K[1, 2])):
            rows.append([f"camera {cam.upper()} {key}", _g(val), _g(std.get(key), 3), "px", src])
        dist = doc.get("distortion") or []
        dnames = doc.get("distortion_names") or [f"d{i}" for i in range(len(dist))]
        dstd = std.get("distortion") or []
        for i, (name, val) in enumerate(zip(dnames, dist, strict=False)):
            rows.append(
                [
                    f"camera {cam.upper()} {name}",
                    _g(val),
                    _g(dstd[i], 3) if i < len(dstd) else "—",
                    "",
                    src,
                ]
            )
        rows.append(
            [f"camera {cam.upper()} reprojection RMS", _g(doc.get("rms_px"), 4), "—", "px", src]
        )
    if found.joint is not None:
        path, doc = found.joint
        src = _rel(path, found.run_dir)
        j = doc.get("joint") or {}
        unit = str(j.get("units", "m"))
        for cam in CAMERAS:
            if j.get(f"position_in_{cam}") is not None:
                vec_rows(
                    f"joint in {cam.upper()} (o_{cam})",
                    j[f"position_in_{cam}"],
                    j.get(f"position_in_{cam}_std"),
                    unit,
                    src,
                    "xyz",
                )
        ba = get_path(doc, "quality.bundle_adjustment", {})
        if isinstance(ba, dict):
            for cam, sec in ba.items():
                if not isinstance(sec, dict):
                    continue
                K = np.asarray(sec.get("camera_matrix", np.full((3, 3), np.nan)), dtype=float)
                istd = sec.get("intrinsics_std") or {}
                vals = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
                for i, name in enumerate(("k1", "k2", "p1", "p2", "k3")):
                    d = sec.get("distortion") or []
                    if i < len(d):
                        vals[name] = d[i]
                for key, val in vals.items():
                    rows.append(
                        [
                            f"camera {str(cam).upper()} {key} (bundle adjustment)",
                            _g(val),
                            _g(istd.get(key), 3),
                            "px" if key in ("fx", "fy", "cx", "cy") else "",
                            src,
                        ]
                    )
        noise = get_path(doc, "quality.estimated_pose_noise", {})
        if isinstance(noise, dict):
            for key, sec in noise.items():
                if isinstance(sec, dict):
                    rows.append(
                        [
                            f"pose noise ({key}): translation",
                            _g(sec.get("sigma_trans"), 3),
                            "—",
                            unit,
                            src,
                        ]
                    )
                    rows.append(
                        [
                            f"pose noise ({key}): rotation",
                            _g(sec.get("sigma_rot_deg"), 3),
                            "—",
                            "deg",
                            src,
                        ]
                    )
    if found.relpose is not None:
        path, doc = found.relpose
        src = _rel(path, found.run_dir)
        rel = doc.get("relative_pose") or {}
        scaled = doc.get("scale") is not None
        unit_b = "B units" if scaled else str(get_path(doc, "units.length", "m"))
        unit_a = "A units" if scaled else unit_b
        vec_rows(
            "R_a_b",
            rel.get("rpy_deg"),
            rel.get("rpy_deg_std"),
            "deg",
            src,
            ["roll", "pitch", "yaw"],
        )
        vec_rows(
            "B's origin in A (t_a_b)",
            rel.get("translation_b_in_a"),
            rel.get("translation_b_in_a_std"),
            unit_b,
            src,
            "xyz",
        )
        j = doc.get("joint") or {}
        vec_rows(
            "joint in A (o_a, relpose)",
            j.get("position_in_a"),
            j.get("position_in_a_std"),
            unit_a,
            src,
            "xyz",
        )
        vec_rows(
            "joint in B (o_b, relpose)",
            j.get("position_in_b"),
            j.get("position_in_b_std"),
            unit_b,
            src,
            "xyz",
        )
        sc = doc.get("scale")
        if isinstance(sc, dict):
            rows.append(
                [
                    "phi_ba = mu_b / mu_a",
                    _g(sc.get("phi_ba")),
                    _g(sc.get("phi_ba_std"), 3),
                    "B units per A unit",
                    src,
                ]
            )
            for key in ("mu_a", "mu_b"):
                if sc.get(key) is not None:
                    rows.append(
                        [
                            key,
                            _g(sc.get(key)),
                            _g(sc.get(f"{key}_std"), 3),
                            f"{key[-1].upper()} units per metre",
                            src,
                        ]
                    )
        noise = get_path(doc, "quality.estimated_pose_noise", None)
        if isinstance(noise, dict):
            rows.append(
                ["pose noise: translation", _g(noise.get("sigma_trans"), 3), "—", unit_b, src]
            )
            rows.append(
                ["pose noise: rotation", _g(noise.get("sigma_rot_deg"), 3), "—", "deg", src]
            )
    return rows


def _collect_warnings(found: _Found) -> None:
    for cam in CAMERAS:
        if cam in found.intrinsics:
            path, doc = found.intrinsics[cam]
            src = _rel(path, found.run_dir)
            for w in doc.get("warnings") or []:
                found.warn(src, str(w))
            dropped = get_path(doc, "images.dropped_outliers", [])
            if isinstance(dropped, list) and dropped:
                found.warn(
                    src,
                    f"{len(dropped)} view(s) dropped as outliers: {', '.join(map(str, dropped))}",
                )
        for p in found.poses.get(cam, []):
            src = _rel(p, found.run_dir)
            try:
                header = read_npz_header(p)
                n = len(read_npz_poses(p))
                skipped = read_npz_quality(p)[1]
            except AcsError as exc:
                found.notes.append(f"{src} could not be read: {exc}")
                continue
            for w in header.get("warnings") or []:
                found.warn(src, str(w))
            if skipped:
                found.warn(
                    src,
                    f"no board pose in {len(skipped)} image(s) (of {n + len(skipped)}): "
                    f"{', '.join(skipped)}",
                )
    for art in (found.joint, found.relpose):
        if art is None:
            continue
        path, doc = art
        src = _rel(path, found.run_dir)
        for w in doc.get("warnings") or []:
            found.warn(src, str(w))
        pairing = get_path(doc, "quality.pairing", None)
        said = any(src == s and "no partner" in t for s, t in found.warnings)
        if (
            isinstance(pairing, dict)
            and (pairing.get("unpaired_a") or pairing.get("unpaired_b"))
            and not said
        ):
            text = (
                f"unpaired samples: {pairing.get('unpaired_a')} of A, {pairing.get('unpaired_b')} "
                f"of B ({pairing.get('pairs')} pairs, by {pairing.get('by')})"
            )
            found.warn(src, text)


# --------------------------------------------------------------------------- the report


def _artifact_rows(found: _Found) -> list[list[str]]:
    rows = []
    items: list[tuple[Path, dict[str, Any]]] = [
        found.intrinsics[c] for c in CAMERAS if c in found.intrinsics
    ]
    items += [a for a in (found.joint, found.relpose) if a is not None]
    for path, doc in items:
        rows.append(
            [
                _rel(path, found.run_dir),
                str(doc.get("schema")),
                str(doc.get("created")),
                str(doc.get("method", "")),
            ]
        )
    for cam in CAMERAS:
        for p in found.poses.get(cam, []):
            try:
                h = read_npz_header(p)
            except AcsError:
                h = {}
            rows.append(
                [
                    _rel(p, found.run_dir),
                    str(h.get("schema", "acscal/poses")),
                    str(h.get("created", "")),
                    str(h.get("method", "")),
                ]
            )
    return rows


def run_report(run_dir: Path, output: Path, config: ReportConfig | None = None) -> ReportRun:
    """Write ``output`` (HTML) and its figures (``<name>_files/*.png``) for a run folder.

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
    if not run_dir.is_dir():
        raise InputError("no such run folder", path=run_dir)
    found = _gather(run_dir)
    if not found.any_file:
        raise InputError(
            "holds no acscal artifact (expected cam_a/intrinsics.yaml, cam_a/poses.npz, "
            "joint.yaml or relpose.yaml, as `acscal run` writes)",
            path=run_dir,
        )
    inputs = [p for p, _ in found.intrinsics.values()]
    inputs += [a[0] for a in (found.joint, found.relpose) if a is not None]
    check_distinct_output(output, inputs)

    created = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = Page(
        f"acscal calibration report: {run_dir.resolve().name}",
        f"acscal {acs_cli.__version__}, {created}, run folder {run_dir}",
    )
    pngs: dict[str, bytes] = {}
    views = _views(found)

    def skip(text: str) -> None:
        found.notes.append(text)
        page.note(text)

    page.section("artifacts", "Artifacts")
    page.table(["file", "schema", "created", "method"], _artifact_rows(found))
    for n in found.notes:
        page.note(n)

    # --- the rig and its trajectory
    page.section("trajectory", "The rig and its trajectory")
    traj: _Trajectory | None = None
    try:
        traj = _trajectory(found)
    except AcsError as exc:
        skip(f"Trajectory skipped: {exc.one_line()}")
    if traj is not None:
        scale, shown = _display_unit(traj.unit)
        pngs["trajectory"] = F.rig_trajectory_figure(
            traj.T_r_a,
            traj.T_r_b,
            traj.joint_a,
            traj.joint_b,
            traj.reference,
            traj.unit,
            views,
            cfg.max_frustums,
            cfg.dpi,
        )
        page.figure(
            pngs["trajectory"],
            f"Both cameras (frustums: A blue, B orange) and the joint's path (green: as A "
            f"sees it; crosses: as B sees it) over {traj.T_r_a.shape[0]} paired frames, in "
            f"camera A's frame at the reference instant; grey lines link each camera to the "
            f"joint. Source: {traj.title}.",
            "3-D view of the rig's trajectory",
        )
        k = traj.reference  # T_r_a[k] is the identity: T_r_b[k] is T_a_b at the reference
        pngs["reference"] = F.rig_reference_figure(
            traj.T_r_b[k], traj.position_in_a, traj.joint_b[k], traj.unit, views, cfg.dpi
        )
        page.figure(
            pngs["reference"],
            "The rig at the reference instant, in camera A's frame: camera B's pose T_a_b and "
            "the joint as each camera locates it.",
            "The rig at the reference instant",
        )
        d = traj.consistency * scale
        page.paragraph(
            f"Joint consistency (distance between the joint as A and as B see it): RMS "
            f"{np.sqrt(np.mean(d**2)):.4g} {shown}, max {d.max():.4g} {shown} over "
            f"{d.size} frames."
        )

    # --- joint-constraint residuals
    page.section("residuals", "Joint-constraint residuals per frame")
    series: list[F.ResidualSeries] = []
    if found.joint is not None:
        try:
            series += _joint_series(found, *found.joint)
        except AcsError as exc:
            skip(f"joint.yaml residuals skipped: {exc.one_line()}")
    else:
        skip("No joint.yaml: no residuals of the joint stage.")
    if traj is not None and found.relpose is not None:
        scale, shown = _display_unit(traj.unit)
        series.append(
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
        skip("No relpose.yaml: no residuals of the relative-pose stage.")
    if series:
        pngs["residuals"] = F.residuals_figure(series, cfg.dpi)
        n_rej = sum(int(s.rejected.sum()) for s in series)
        page.figure(
            pngs["residuals"],
            f"Residual of the joint constraint per frame; frames the estimator rejected as "
            f"outliers are red crosses ({n_rej} in all); dashed: RMS of the frames used.",
            "Joint-constraint residuals per frame",
        )

    # --- reprojection
    page.section("reprojection", "Reprojection errors")
    try:
        rep = _reprojection(found)
    except (AcsError, TypeError, ValueError) as exc:
        rep = []
        text = exc.one_line() if isinstance(exc, AcsError) else f"unexpected value ({exc})"
        skip(f"Reprojection errors skipped: {text}")
    if rep:
        pngs["reprojection"] = F.reprojection_figure(rep, cfg.dpi)
        page.figure(
            pngs["reprojection"],
            "Left: RMS reprojection error of each view of the intrinsics calibration. Right: "
            "RMS reprojection error of each image's board pose (PnP with the calibrated "
            "intrinsics), per poses file.",
            "Reprojection error per view and per camera",
        )
    elif not found.intrinsics and not found.poses:
        skip("No intrinsics.yaml and no poses: no reprojection errors.")

    # --- coverage
    page.section("coverage", "Image coverage of the detected corners")
    try:
        cov = _coverage(found)
    except AcsError as exc:
        cov = []
        skip(f"Coverage skipped: {exc.one_line()}")
    if cov:
        pngs["coverage"] = F.coverage_figure(cov, dpi=cfg.dpi)
        page.figure(
            pngs["coverage"],
            "Where in each camera's image the board's corners were detected (every posed image "
            "of the run): corners per cell of a 16x12 grid, each corner a white dot. Empty "
            "borders mean the lens distortion there is extrapolated.",
            "Image coverage of the detected corners",
        )
    else:
        skip("No poses with corners (cam_<x>/*.npz from acscal poses): no coverage figure.")

    # --- estimates
    page.section("estimates", "Estimates and standard deviations")
    try:
        rows = _estimates(found)
    except (TypeError, ValueError, IndexError, KeyError, AttributeError) as exc:
        rows = []
        skip(f"Estimates table skipped: an artifact holds an unexpected value ({exc}).")
    if rows:
        page.table(["quantity", "value", "std (1 sigma)", "unit", "source"], rows, numeric=(1, 2))
    else:
        skip("No estimates: no intrinsics, joint or relpose artifact.")

    # --- warnings
    page.section("warnings", "Warnings")
    for w in cfg.extra_warnings:
        found.warn("run", w)
    _collect_warnings(found)
    warnings = [f"{src}: {text}" for src, text in found.warnings]
    if warnings:
        page.items(warnings, "warn")
    else:
        page.paragraph("No warnings.")
    if found.notes:
        page.section("notes", "Sections skipped")
        page.items(found.notes)

    # --- write
    fig_dir = figures_dir_for(output)
    written = []
    for key, name in FIGURE_NAMES.items():
        target = fig_dir / name
        if key in pngs:
            atomic_write_bytes(target, pngs[key])
            written.append(target)
        elif target.is_file():
            try:
                target.unlink()  # a figure of an earlier report that this one does not have
            except OSError:
                pass
    atomic_write_text(output, page.render())
    return ReportRun(output, fig_dir, written, list(found.notes), warnings)
