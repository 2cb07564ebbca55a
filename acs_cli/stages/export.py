"""The export stage: ``acscal export`` writes a calibration for other tools.

A relative pose (``relpose.yaml``, two cameras ``a`` and ``b``) or a rig (``rig.yaml``)
exports as

- ``kalibr``: a Kalibr camchain (:mod:`acs_cli.io.rig_export`) with every camera's
  intrinsics;
- ``opencv``: a relative pose as one ``cv2.FileStorage`` file (``R``, ``T`` of ``T_b_a``,
  as ``cv2.stereoCalibrate`` names them, and each camera's intrinsics when known);
- ``ros``: one ROS ``camera_info`` YAML per camera, ``-o`` being a folder;
- ``urdf``: a rig's kinematic tree.

Intrinsics (:func:`find_intrinsics`) are, per camera, the file given (``--intrinsics``),
else the bundle-adjusted ones the artifact records (the final ones), else
``cam_<camera>/intrinsics.yaml`` beside the artifact (a run folder's layout).

Lengths are exported in metres only (:func:`relpose_metres`, :func:`rig_metres`): from
a known unit, from the metric joint's ``mu_a``, ``mu_b`` of an unknown-scale relative pose,
or from an explicit ``scale`` (metres per unit); otherwise the export is refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.artifacts import load_yaml_file
from acs_cli.io.atomic import check_distinct_output, check_writable
from acs_cli.io.export import (
    METRES_PER_UNIT,
    check_ros_camera_name,
    opencv_camera_values,
    write_opencv_yaml,
    write_ros_camera_info,
)
from acs_cli.io.handeye_export import HandEyeExport, write_handeye
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.joint import BundleSection
from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.validate import MAX_MAGNITUDE
from acs_cli.io.verdict import VerdictSection, weak_marks

if TYPE_CHECKING:  # rig.yaml's reader is imported where a rig is exported
    from acs_cli.io.rig import RigArtifact

__all__ = [
    "EXPORT_FORMATS",
    "METRES_PER_UNIT",
    "find_intrinsics",
    "relpose_metres",
    "rig_metres",
    "run_export",
    "run_rig_export",
]

EXPORT_FORMATS = ("kalibr", "opencv", "ros", "urdf", "handeye")
#: The formats of a rig (``rig.yaml``).
RIG_FORMATS = ("kalibr", "ros", "urdf", "handeye")
#: A relative pose's cameras: the key by which options name them, and their default names.
PAIR_CAMERAS = {"a": "cam_a", "b": "cam_b"}


def _pair_keys(given: Mapping[str, Any], option: str) -> dict[str, Any]:
    """A relative pose's per-camera options by ``a``/``b`` (``cam_a``, ``cam_b`` too)."""
    out: dict[str, Any] = {}
    for name, value in given.items():
        key = {"a": "a", "b": "b", "cam_a": "a", "cam_b": "b"}.get(name)
        if key is None:
            raise InputError(f"{option} {name}=...: a relative pose's cameras are a and b")
        if key in out:
            raise InputError(f"{option}: camera {key} given twice")
        out[key] = value
    return out


def _check_output(output: Path, fmt: str, inputs: Sequence[Path]) -> None:
    """Refuse an output that is an input, or (a file format) that cannot be written, first."""
    check_distinct_output(output, inputs)
    if fmt != "ros":  # a folder: its files are checked once named
        check_writable(output)


def _check_scale(scale: float | None) -> None:
    if scale is not None and not (math.isfinite(scale) and 0 < scale <= MAX_MAGNITUDE):
        raise InputError(
            f"--scale must be a positive number of metres per unit (at most "
            f"{MAX_MAGNITUDE:.0e}), got {scale}"
        )


# --------------------------------------------------------------------------------------
# intrinsics


def _existing(path: str, base: Path) -> Path | None:
    """``path`` as recorded (relative to the working folder), else relative to ``base``."""
    if not path:
        return None
    for p in (Path(path), base / path):
        try:
            if p.is_file():
                return p
        except (OSError, ValueError):  # a name the system cannot hold (NUL, too long)
            return None
    return None


def find_intrinsics(
    given: Path | None, beside: Path, bundle: BundleSection | None, artifact: Path
) -> tuple[IntrinsicsArtifact | None, str]:
    """One camera's intrinsics for an export, and where they came from (in words).

    In order: the file ``given``; the bundle adjustment's refined ``K`` and coefficients
    recorded in ``artifact`` (``bundle``; the image size from ``beside`` or from the
    intrinsics file the bundle adjustment started from); the file ``beside``.

    Parameters
    ----------
    given : Path or None
        ``--intrinsics``: an ``acscal/intrinsics`` file.
    beside : Path
        Where ``acscal run`` writes the camera's intrinsics (``cam_<x>/intrinsics.yaml``).
    bundle : BundleSection or None
        The camera's bundle adjustment in the artifact, if any.
    artifact : Path
        The ``relpose.yaml`` or ``rig.yaml`` exported.

    Returns
    -------
    tuple
        The intrinsics (None when none were found) and their source.

    Raises
    ------
    InputError
        An unreadable or malformed intrinsics file.
    """
    if given is not None:
        return IntrinsicsArtifact.load(given), f"{given} (--intrinsics)"
    base = IntrinsicsArtifact.load(beside) if beside.is_file() else None
    if bundle is not None:
        start = _existing(bundle.intrinsics_file, artifact.parent)
        sized = (
            base if base is not None else None if start is None else IntrinsicsArtifact.load(start)
        )
        if sized is not None:
            refined = IntrinsicsArtifact(
                model=bundle.model,
                image_size=sized.image_size,
                camera_matrix=np.asarray(bundle.camera_matrix, dtype=float),
                distortion=np.asarray(bundle.distortion, dtype=float),
            )
            return refined, f"bundle-adjusted, from {artifact.name}"
    if base is not None:
        return base, str(beside)
    return None, "none found"


# --------------------------------------------------------------------------------------
# lengths


def relpose_metres(art: RelposeArtifact, scale: float | None) -> tuple[float, float, str]:
    """Metres per unit of camera A's and of camera B's lengths in a ``relpose.yaml``.

    Under unknown scale (a ``scale`` section) B's lengths are in B's trajectory units:
    metres come from ``scale`` (metres per B unit; A's: ``scale * phi_ba``), else from the
    metric joint's ``mu_a``, ``mu_b`` (trajectory units per metre). Under known scale they
    are in ``units.length``: ``scale`` when given, else :data:`METRES_PER_UNIT`.

    Returns
    -------
    tuple
        ``(metres per A unit, metres per B unit, how, in words)``.

    Raises
    ------
    InputError
        Lengths that cannot be put in metres: unknown scale without a metric joint or
        ``scale``, or a unit that is not in :data:`METRES_PER_UNIT` without ``scale``; the
        message says how to get a metric result.
    """
    _check_scale(scale)
    where = art.source
    if art.scale is not None:
        if scale is not None:
            return scale * art.scale.phi_ba, scale, f"--scale {scale:g} m per unit of B"
        mu_a, mu_b = art.scale.mu_a, art.scale.mu_b
        if mu_a is not None and mu_b is not None and min(mu_a, mu_b) > 0:
            if math.isfinite(mu_a) and math.isfinite(mu_b):
                return 1.0 / mu_a, 1.0 / mu_b, "the metric joint's mu_a, mu_b"
        raise InputError(
            "the relative pose has unknown scale (--unknown-scale): its lengths are in camera "
            "B's trajectory units, not metres, and would be exported wrong. Rerun acscal "
            "relpose with --joint-metric JOINT (a joint measured in metres, e.g. acscal joint "
            "on board poses) to record mu_a and mu_b, or give --scale METRES_PER_UNIT "
            "(metres per unit of camera B's trajectory)",
            path=where,
        )
    unit = art.length_unit
    if scale is not None:
        return scale, scale, f"--scale {scale:g} m per {unit}"
    if unit in METRES_PER_UNIT:
        m = METRES_PER_UNIT[unit]
        return m, m, f"recorded in {unit}"
    raise InputError(
        f"the relative pose's lengths are in {unit!r} (--length-unit), which acscal cannot "
        f"convert to metres ({', '.join(METRES_PER_UNIT)}); give --scale METRES_PER_UNIT",
        path=where,
    )


def rig_metres(length_unit: str, scale: float | None, where: str | None) -> tuple[float, str]:
    """Metres per unit of a rig's lengths (the reference camera's), and how, in words.

    Raises
    ------
    InputError
        A unit other than :data:`METRES_PER_UNIT` (the reference camera's scale is
        unknown) without ``scale``.
    """
    _check_scale(scale)
    if scale is not None:
        return scale, f"--scale {scale:g} m per {length_unit}"
    if length_unit in METRES_PER_UNIT:
        return METRES_PER_UNIT[length_unit], f"recorded in {length_unit}"
    raise InputError(
        f"the rig's lengths are in {length_unit} (the reference camera's trajectory has "
        "unknown scale), not metres. Give --scale METRES_PER_UNIT (metres per unit of the "
        "reference camera's trajectory), or make the reference camera a metric one "
        "(reference: {camera: ...} in the rig config)",
        path=where,
    )


def _known(cams: Mapping[str, IntrinsicsArtifact | None]) -> dict[str, IntrinsicsArtifact]:
    """The cameras whose intrinsics were found."""
    return {c: v for c, v in cams.items() if v is not None}


def _export_notes(
    artifact: str,
    verdict: VerdictSection | None,
    warnings: Sequence[str],
    cams: Mapping[str, IntrinsicsArtifact | None],
    sources: Mapping[str, str],
) -> list[str]:
    """The comment lines of an export: the artifact's weak mark and warnings, and a mark for
    each camera whose intrinsics file is a weak result."""
    out = weak_marks(artifact, verdict) + _warning_notes(artifact, warnings)
    for c, intr in cams.items():
        if intr is not None:
            out += weak_marks(f"the intrinsics of {c} ({sources.get(c, '')})", intr.verdict)
    return out


def _warning_notes(artifact: str, warnings: Sequence[str]) -> list[str]:
    """Comment lines that mark a result exported despite its artifact's warnings."""
    if not warnings:
        return []
    return [
        f"WARNING: {artifact} carries {len(warnings)} warning(s); this calibration may be "
        "poorly determined:",
        *(f"WARNING: {w}" for w in warnings),
    ]


# --------------------------------------------------------------------------------------
# writing


def _write_ros(
    folder: Path,
    cameras: Mapping[str, IntrinsicsArtifact | None],
    names: Mapping[str, str],
    sources: Mapping[str, str],
    notes: Sequence[str],
) -> list[Path]:
    """One ``<name>.yaml`` camera_info per camera in ``folder`` (``names``: camera key to
    its ROS name); refuses a camera without intrinsics before writing anything."""
    known = _known(cameras)
    missing = [names[c] for c in cameras if c not in known]
    if missing:
        raise InputError(
            "a ROS camera_info needs the camera's intrinsics; none found for "
            + ", ".join(missing)
            + " (give --intrinsics CAMERA=intrinsics.yaml)"
        )
    if folder.is_file():
        raise InputError(
            "--format ros writes a folder of camera_info files; this is a file", path=folder
        )
    targets = {c: folder / f"{check_ros_camera_name(names[c])}.yaml" for c in cameras}
    if len(set(targets.values())) != len(targets):
        raise InputError("two cameras have the same --camera-name")
    for p in targets.values():
        check_writable(p)
    for c, intr in known.items():
        write_ros_camera_info(
            targets[c],
            intr.camera_matrix,
            intr.distortion,
            intr.image_size,
            intr.model,
            names[c],
            comments=[f"exported by acscal: camera {names[c]}, intrinsics {sources[c]}", *notes],
        )
    return list(targets.values())


def run_rig_export(
    rig_file: Path,
    output: Path,
    fmt: str,
    *,
    intrinsics: dict[str, Path] | None = None,
    camera_names: Mapping[str, str] | None = None,
    scale: float | None = None,
    robot_name: str = "acs_rig",
    doc: Any = None,
    base_frame: str = "base_link",
    board_frame: str = "board",
    limit_margin_deg: float | None = None,
) -> dict[str, Any]:
    """Export ``rig.yaml`` as a Kalibr camchain, ROS camera_infos, a URDF or a hand-eye
    calibration (``handeye``: :func:`handeye_of_rig`).

    Intrinsics come per camera as :func:`find_intrinsics` finds them (``intrinsics``: camera
    name to ``intrinsics.yaml``; ``cam_<name>/intrinsics.yaml`` beside ``rig.yaml``).
    Lengths are put in metres (:func:`rig_metres`). ``camera_names`` name the ROS
    camera_info files (default: the rig's camera names). ``cam_overlaps`` are empty: a rig
    does not record which cameras share views. A URDF's hinge limits are each hinge's
    observed angle range widened by ``limit_margin_deg`` on either side
    (:func:`acs_cli.io.rig_export.urdf_from_rig`).

    Returns
    -------
    dict
        ``format``, ``output``, ``keys`` (the cameras), ``written`` (paths),
        ``intrinsics`` (camera to source) and ``warnings`` (the rig's).

    Raises
    ------
    InputError
        A format a rig does not have, a bad ``rig.yaml``, intrinsics of an unknown camera,
        a camera without intrinsics (kalibr, ros), lengths that cannot be put in metres.
    """
    from acs_cli.io.rig import RigArtifact
    from acs_cli.io.rig_export import DEFAULT_LIMIT_MARGIN_DEG, rig_in_metres, write_rig_export

    if fmt not in RIG_FORMATS:
        raise InputError(f"a rig exports as {', '.join(RIG_FORMATS)}, not {fmt!r}", path=rig_file)
    found = dict(intrinsics or {})
    _check_output(output, fmt, [rig_file, *found.values()])
    rig = RigArtifact.load(rig_file) if doc is None else RigArtifact.from_parsed(doc, rig_file)
    for option, given in (("--intrinsics", found), ("--camera-name", camera_names or {})):
        unknown = [c for c in given if c not in rig.cameras]
        if unknown:
            raise InputError(
                f"{option} {unknown[0]}=...: the rig has no camera {unknown[0]} "
                f"({', '.join(rig.cameras)})"
            )
    cams: dict[str, IntrinsicsArtifact | None] = {}
    sources: dict[str, str] = {}
    if fmt != "urdf":
        for cam in rig.cameras:
            cams[cam], sources[cam] = find_intrinsics(
                found.get(cam),
                rig_file.parent / f"cam_{cam}" / "intrinsics.yaml",
                rig.bundle_adjustment.get(cam),
                rig_file,
            )
    notes = _export_notes(rig_file.name, rig.verdict, rig.warnings, cams, sources)
    info: dict[str, Any] = {
        "format": fmt,
        "output": str(output),
        "keys": list(rig.cameras),
        "intrinsics": sources,
        "warnings": list(rig.warnings),
        "verdict": "good" if rig.verdict is None else rig.verdict.level,
    }
    if fmt == "ros":
        names = {c: (camera_names or {}).get(c, c) for c in rig.cameras}
        info["written"] = [str(p) for p in _write_ros(output, cams, names, sources, notes)]
        return info
    m, how = rig_metres(rig.length_unit, scale, str(rig_file))
    if fmt == "handeye":
        names = {c: (camera_names or {}).get(c, c) for c in rig.cameras}
        he, joint = handeye_of_rig(rig, m, names, base_frame, board_frame, robot_name)
        head = (
            f"acscal export (handeye) of {rig_file.name}, joint {joint}: the camera's pose in "
            f"the robot's effector frame; lengths in metres ({how})"
        )
        notes = [head, *notes]
        doc_out = write_handeye(output, he, notes)
        info["written"] = [str(output)]
        info["static_transform_publisher"] = doc_out["acscal"]["static_transform_publisher"]
        return info
    notes = [f"lengths in metres ({how})", *notes]
    if fmt == "kalibr":
        notes = [f"intrinsics of {c}: {sources[c]}" for c in rig.cameras] + notes
    write_rig_export(
        output,
        rig_in_metres(rig, m),
        fmt,
        intrinsics=_known(cams) if fmt == "kalibr" else None,
        robot_name=robot_name,
        notes=notes,
        limit_margin_deg=DEFAULT_LIMIT_MARGIN_DEG if limit_margin_deg is None else limit_margin_deg,
    )
    info["written"] = [str(output)]
    return info


def handeye_of_rig(
    rig: RigArtifact,
    metres: float,
    names: Mapping[str, str],
    base_frame: str,
    board_frame: str,
    namespace: str,
) -> tuple[HandEyeExport, str]:
    """A rig's hand-eye calibration: its one rigid joint between a camera and a body with
    poses only (the robot's flange: ``cameras.<body>.pose_only``), as the camera's pose in
    the flange's frame, with the board in the robot's base when the bundle found it.

    Raises
    ------
    InputError
        No such joint, or several.
    """
    found = []
    for name, j in rig.joints.items():
        if j.type != "rigid" or j.T_q_p is None:
            continue
        p, q = j.between
        bodies = [c for c in (p, q) if rig.cameras[c].pose_only is not None]
        if len(bodies) == 1:
            found.append((name, j, bodies[0]))
    if len(found) != 1:
        raise InputError(
            "a hand-eye export needs the rig's one rigid joint between a camera and a body "
            f"with poses only (a robot's flange in the bundle adjustment); found {len(found)}",
            path=rig.source,
        )
    name, j, body = found[0]
    p, q = j.between
    camera = q if body == p else p
    T = np.asarray(j.T_q_p, dtype=float).copy()  # maps p into q
    std = j.T_q_p_std
    if body == p:  # T_q_p = T_camera_flange: the other way round, and its std
        R = T[:3, :3].copy()
        T = se3.invert_transforms(T)
        if std is not None:
            # (R Exp(d), t + e)^-1 = (R' Exp(-R d), t' + [t']x d - R^T e) to first order; the
            # stds as a diagonal covariance (rig.yaml keeps no correlations)
            Cd, Ce = np.diag(np.radians(std[0]) ** 2), np.diag(np.asarray(std[1]) ** 2)
            K = se3.skew(T[:3, 3])
            rot = np.degrees(np.sqrt(np.diag(R @ Cd @ R.T)))
            trans = np.sqrt(np.diag(K @ Cd @ K.T + R.T @ Ce @ R))
            std = (rot, trans)
    T[:3, 3] *= metres
    if std is not None:
        std = (np.asarray(std[0], float), metres * np.asarray(std[1], float))
    po = rig.cameras[body].pose_only
    Z = None if po is None else po.T_world_board.get(camera)
    Z_std = None if po is None else po.T_world_board_std.get(camera)
    if Z is not None:
        Z = np.asarray(Z, dtype=float).copy()
        Z[:3, 3] *= metres
    if Z_std is not None:
        Z_std = (np.asarray(Z_std[0], float), metres * np.asarray(Z_std[1], float))
    he = HandEyeExport(
        T, std, Z, Z_std, base_frame, names.get(body, body), names.get(camera, camera),
        board_frame, f"{namespace}_eye_on_hand",
    )  # fmt: skip
    return he, name


def _pair_overlap(art: RelposeArtifact, relpose: Path) -> bool:
    """Whether the pair shared views: its joint came from ``acscal joint --overlap``."""
    entry = art.inputs.get("joint")
    path = (
        _existing(str(entry.get("path", "")), relpose.parent) if isinstance(entry, dict) else None
    )
    if path is None:
        return False
    try:
        doc = load_yaml_file(path)
    except InputError:
        return False
    return isinstance(doc, dict) and doc.get("scenario") == "overlap"


def run_export(
    relpose: Path,
    output: Path,
    fmt: str,
    *,
    intrinsics: Mapping[str, Path] | None = None,
    camera_names: Mapping[str, str] | None = None,
    scale: float | None = None,
    robot_name: str = "acs_rig",
    base_frame: str = "base_link",
    board_frame: str = "board",
    limit_margin_deg: float | None = None,
) -> dict[str, Any]:
    """Export ``relpose.yaml`` (or a rig's ``rig.yaml``, see :func:`run_rig_export`).

    A relative pose exports as ``kalibr`` (``cam0`` = A, ``cam1`` = B with ``T_cn_cnm1 =
    T_b_a``; ``cam_overlaps`` when its joint came from overlapping views), ``opencv`` (one
    file: ``R``, ``T``, ``T_b_a``, ``reference``, the joint, ``phi_ba``, ``length_unit`` and
    each camera's intrinsics, when known, as a map ``cam_a``, ``cam_b``) or ``ros`` (a
    camera_info per camera in the folder ``output``). Lengths are put in metres
    (:func:`relpose_metres`); the artifact's warnings are copied into the file as comments.

    Parameters
    ----------
    relpose : Path
        ``relpose.yaml`` or ``rig.yaml``.
    output : Path
        The file to write (``ros``: the folder).
    fmt : {"kalibr", "opencv", "ros", "urdf"}
    intrinsics : mapping of camera to Path, optional
        Intrinsics files by camera (``a``, ``b`` or ``cam_a``, ``cam_b`` for a pair);
        else as :func:`find_intrinsics` finds them.
    camera_names : mapping of camera to str, optional
        The cameras' names (ROS ``camera_name`` and file name, default topics); default
        ``cam_a``, ``cam_b`` (a rig: its camera names).
    scale : float, optional
        Metres per unit of the artifact's lengths (unknown scale: of camera B's trajectory).
    robot_name : str
        ``urdf``: the robot's name.
    limit_margin_deg : float, optional
        ``urdf``: degrees added on either side of each hinge's observed angle range
        (default :data:`acs_cli.io.rig_export.DEFAULT_LIMIT_MARGIN_DEG`).

    Returns
    -------
    dict
        What was written: ``format``, ``output``, ``keys``, ``written`` (paths),
        ``intrinsics`` (camera to source) and ``warnings`` (the artifact's).

    Raises
    ------
    InputError
        An unknown format, an unreadable or malformed artifact, an output that would
        overwrite an input, missing intrinsics (kalibr, ros), lengths that cannot be put
        in metres (kalibr, opencv).
    """
    if fmt not in EXPORT_FORMATS:
        raise InputError(f"unknown export format {fmt!r}; use one of {', '.join(EXPORT_FORMATS)}")
    doc = load_yaml_file(relpose, "an acscal artifact (YAML)")  # read once: rig or relpose
    if isinstance(doc, dict) and doc.get("schema") == "acscal/rig":
        return run_rig_export(
            relpose,
            output,
            fmt,
            intrinsics=dict(intrinsics or {}),
            camera_names=camera_names,
            scale=scale,
            robot_name=robot_name,
            doc=doc,
            base_frame=base_frame,
            board_frame=board_frame,
            limit_margin_deg=limit_margin_deg,
        )
    if fmt in ("urdf", "handeye"):
        raise InputError(f"{fmt} exports a rig (rig.yaml from acscal run)", path=relpose)
    given = _pair_keys(intrinsics or {}, "--intrinsics")
    _check_output(output, fmt, [relpose, *given.values()])
    art = RelposeArtifact.from_parsed(doc, relpose)
    names = {**PAIR_CAMERAS, **_pair_keys(camera_names or {}, "--camera-name")}
    cams: dict[str, IntrinsicsArtifact | None] = {}
    sources: dict[str, str] = {}
    for x in PAIR_CAMERAS:
        cams[x], sources[x] = find_intrinsics(
            given.get(x),
            relpose.parent / f"cam_{x}" / "intrinsics.yaml",
            art.quality.bundle_adjustment.get(x),
            relpose,
        )
    notes = _export_notes(relpose.name, art.verdict, art.warnings, cams, sources)
    info: dict[str, Any] = {
        "format": fmt,
        "output": str(output),
        "keys": [names["a"], names["b"]],
        "intrinsics": {names[x]: sources[x] for x in PAIR_CAMERAS},
        "warnings": list(art.warnings),
        "verdict": "good" if art.verdict is None else art.verdict.level,
    }
    if fmt == "ros":
        written = _write_ros(output, cams, names, sources, notes)
        info["written"] = [str(p) for p in written]
        return info

    m_a, m_b, how = relpose_metres(art, scale)
    T_b_a = np.array(art.relative_pose.T_b_a, dtype=float)
    T_b_a[:3, 3] *= m_b
    ref = int(art.relative_pose.reference)
    notes = [f"lengths in metres ({how})", *notes]
    if fmt == "kalibr":
        from acs_cli.io.atomic import atomic_write_text
        from acs_cli.io.rig_export import kalibr_camchain_from_pair

        text = kalibr_camchain_from_pair(
            T_b_a,
            _known({names[x]: cams[x] for x in PAIR_CAMERAS}),
            names=(names["a"], names["b"]),
            reference=ref,
            overlap=_pair_overlap(art, relpose),
            notes=[*(f"intrinsics of {names[x]}: {sources[x]}" for x in PAIR_CAMERAS), *notes],
        )
        atomic_write_text(output, text)
        info["written"] = [str(output)]
        return info

    mats: dict[str, Any] = {
        "R": T_b_a[:3, :3],
        "T": T_b_a[:3, 3:4],
        "T_b_a": T_b_a,
        "R_b_a": T_b_a[:3, :3],
        "t_b_a": T_b_a[:3, 3:4],
        "reference": ref,
    }
    if art.joint is not None:
        for which, m in (("a", m_a), ("b", m_b)):
            pos = art.joint.position(which)
            if pos is not None:
                mats[f"joint_in_{which}"] = m * np.asarray(pos, dtype=float)[:, None]
    if art.scale is not None:
        mats["phi_ba"] = float(art.scale.phi_ba)
    mats["length_unit"] = "m"
    if art.warnings:  # also as a key: a JSON FileStorage has no comments
        mats["warnings"] = "; ".join(art.warnings)
    if art.verdict is not None and art.verdict.weak:
        mats["verdict"] = art.verdict.level + (
            " (--accept-weak)" if art.verdict.accepted_weak else ""
        )
    for x in PAIR_CAMERAS:
        intr = cams[x]
        if intr is not None:
            values = opencv_camera_values(
                intr.camera_matrix, intr.distortion, intr.image_size, intr.model
            )
            mats[f"cam_{x}"] = {"camera_name": names[x], **values}
    comments = [
        "acscal relative pose: R, T (= T_b_a) map camera A's frame into camera B's "
        f"(p_b = R p_a + T, as cv2.stereoCalibrate), at the reference instant (paired frame "
        f"{ref}) of an articulated pair",
        *(f"intrinsics of {names[x]} (map cam_{x}): {sources[x]}" for x in PAIR_CAMERAS),
        *notes,
    ]
    write_opencv_yaml(output, mats, comments=comments)
    info["keys"] = list(mats)
    info["written"] = [str(output)]
    return info
