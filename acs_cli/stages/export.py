"""The export stage: ``acscal export`` writes a calibration for other tools."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from acs_cli.errors import InputError
from acs_cli.io.artifacts import load_yaml_file
from acs_cli.io.atomic import check_distinct_output
from acs_cli.io.export import write_camchain_yaml, write_opencv_yaml
from acs_cli.io.relpose import RelposeArtifact

EXPORT_FORMATS = ("kalibr", "opencv", "urdf")


def run_rig_export(
    rig_file: Path,
    output: Path,
    fmt: str,
    *,
    intrinsics: dict[str, Path] | None = None,
    robot_name: str = "acs_rig",
    doc: Any = None,
) -> dict[str, Any]:
    """Export ``rig.yaml`` as a URDF or a Kalibr camchain of every camera.

    Intrinsics (for Kalibr) come from ``intrinsics`` (camera name to ``intrinsics.yaml``)
    or, for cameras not given there, from ``cam_<name>/intrinsics.yaml`` beside
    ``rig.yaml`` (where ``acscal run`` writes them) when it exists.
    """
    from acs_cli.io.rig import RigArtifact
    from acs_cli.io.rig_export import write_rig_export

    if fmt not in ("kalibr", "urdf"):
        raise InputError(f"a rig exports as kalibr or urdf, not {fmt!r}", path=rig_file)
    found = dict(intrinsics or {})
    check_distinct_output(output, [rig_file, *found.values()])
    rig = RigArtifact.load(rig_file) if doc is None else RigArtifact.from_parsed(doc, rig_file)
    unknown = [c for c in found if c not in rig.cameras]
    if unknown:
        raise InputError(
            f"--intrinsics {unknown[0]}=...: the rig has no camera {unknown[0]} "
            f"({', '.join(rig.cameras)})"
        )
    for cam in rig.cameras:
        beside = rig_file.parent / f"cam_{cam}" / "intrinsics.yaml"
        if cam not in found and beside.is_file():
            found[cam] = beside
    write_rig_export(
        output,
        rig,
        fmt,
        intrinsics=found if fmt == "kalibr" else None,
        robot_name=robot_name,
    )
    return {"format": fmt, "output": str(output), "keys": list(rig.cameras)}


def run_export(
    relpose: Path,
    output: Path,
    fmt: str,
    *,
    intrinsics: dict[str, Path] | None = None,
    robot_name: str = "acs_rig",
) -> dict[str, Any]:
    """Export ``relpose.yaml`` (or a rig's ``rig.yaml``, see :func:`run_rig_export`) as a
    Kalibr camchain or an OpenCV FileStorage YAML (a rig: a Kalibr camchain or a URDF).

    Reads ``relative_pose.T_b_a`` (a rigid 4x4), ``relative_pose.reference``,
    ``joint.position_in_a/b``, ``scale.phi_ba`` and ``units.length`` through
    :class:`~acs_cli.io.relpose.RelposeArtifact`.

    Returns
    -------
    dict
        What was written (``format``, ``output``, ``keys``).

    Raises
    ------
    InputError
        An unknown format, an unreadable or malformed ``relpose.yaml``, or an output that
        would overwrite it.
    """
    if fmt not in EXPORT_FORMATS:
        raise InputError(f"unknown export format {fmt!r}; use one of {', '.join(EXPORT_FORMATS)}")
    doc = load_yaml_file(relpose, "an acscal artifact (YAML)")  # read once: rig or relpose
    if isinstance(doc, dict) and doc.get("schema") == "acscal/rig":
        return run_rig_export(
            relpose, output, fmt, intrinsics=intrinsics, robot_name=robot_name, doc=doc
        )
    if fmt == "urdf":
        raise InputError("urdf exports a rig (rig.yaml from acscal run)", path=relpose)
    check_distinct_output(output, [relpose])
    art = RelposeArtifact.from_parsed(doc, relpose)
    T_b_a = art.relative_pose.T_b_a
    if fmt == "kalibr":
        write_camchain_yaml(output, [{"name": "cam_a"}, {"name": "cam_b", "T_cn_cnm1": T_b_a}])
        return {"format": fmt, "output": str(output), "keys": ["cam0", "cam1"]}
    mats: dict[str, Any] = {
        "T_b_a": T_b_a,
        "R_b_a": T_b_a[:3, :3],
        "t_b_a": T_b_a[:3, 3:4],
        "reference": int(art.relative_pose.reference),
    }
    if art.joint is not None:
        for which in ("a", "b"):
            pos = art.joint.position(which)
            if pos is not None:
                mats[f"joint_in_{which}"] = pos[:, None]
    if art.scale is not None:
        mats["phi_ba"] = float(art.scale.phi_ba)
    mats["length_unit"] = art.length_unit
    write_opencv_yaml(output, mats)
    return {"format": fmt, "output": str(output), "keys": list(mats)}
