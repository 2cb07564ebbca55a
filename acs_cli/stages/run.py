"""The pipeline stage: ``acscal run CONFIG`` (intrinsics, poses, joint and relpose in one go).

:func:`load_run_config` (:mod:`acs_cli.io.config`) reads and checks a run configuration
(``schema: acscal/run-config``, see ``configs/*.yaml``); :func:`run_pipeline` runs the
stages it names, each only when its inputs changed since its last successful run.

A stage's *stamp* is the SHA-256 of its name, the tool's version, its options and the
SHA-256 of each input file (or folder of images). After a stage succeeds, its stamp and the
SHA-256 of each output are stored in ``<output>/.acscal-run.yaml`` (written atomically after
every stage). A later run skips the stage when its stamp is unchanged and its outputs are
still there, unmodified. Downstream stages read upstream outputs, so a rerun upstream
propagates downstream through the outputs' content hashes.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

import acs_cli
from acs_cli.errors import AcsError, DegenerateMotionError, InputError
from acs_cli.io.artifacts import load_yaml_file, sha256_of
from acs_cli.io.atomic import atomic_write_text
from acs_cli.io.bag import is_bag_path
from acs_cli.io.config import (
    CONFIG_SCHEMA,
    CameraSpec,
    JointSpec,
    RelposeSpec,
    RigCameraSpec,
    RigRunConfig,
    RunConfig,
    load_run_config,
    parse_run_config,
)
from acs_cli.io.images import list_images
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.video import EVERY_FRAME, FrameSelection, is_video_path

if TYPE_CHECKING:
    from acs_cli.core.targets import MarkerTarget

__all__ = [
    "CONFIG_SCHEMA",
    "STAGE_KINDS",
    "STATE_FILE",
    "CameraSpec",
    "JointSpec",
    "PipelineRun",
    "RelposeSpec",
    "RunConfig",
    "StageResult",
    "load_run_config",
    "parse_run_config",
    "run_pipeline",
]

STATE_SCHEMA = "acscal/run-state"
STATE_FILE = ".acscal-run.yaml"
#: Stage kinds, in the order they run (``--only`` takes one of them).
STAGE_KINDS = ("intrinsics", "poses", "joint", "relpose", "rig")
#: The HTML report every run ends with (regenerated each time, see :func:`write_run_report`).
REPORT_FILE = "report.html"

StageCallback = Callable[["StageResult"], None]


# --------------------------------------------------------------------------- pipeline


@dataclass
class StageResult:
    """One stage of a run: what it did and its headline numbers."""

    stage: str
    status: str  # "ran", "skipped", "reused", "not selected"
    outputs: list[Path]
    numbers: str = ""
    seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class PipelineRun:
    """What :func:`run_pipeline` did."""

    config: RunConfig | RigRunConfig
    stages: list[StageResult]
    state_file: Path
    seconds: float

    @property
    def ran(self) -> list[str]:
        return [s.stage for s in self.stages if s.status == "ran"]

    @property
    def skipped(self) -> list[str]:
        return [s.stage for s in self.stages if s.status == "skipped"]


@dataclass
class _Stage:
    stage: str
    kind: str
    inputs: dict[str, Path]
    options: dict[str, Any]
    outputs: list[Path]
    #: runs the stage, given its trajectory inputs already read (by role)
    action: Callable[[Mapping[str, PosesArtifact]], list[str]]
    #: the inputs that are trajectories (role: format): each is read once, for the stamp's
    #: hash and for the stage
    poses: dict[str, str] = field(default_factory=dict)


def _stamp(stage: _Stage, input_hashes: Mapping[str, str]) -> str:
    doc = {
        "stage": stage.stage,
        "tool": acs_cli.__version__,
        "options": stage.options,
        "inputs": dict(input_hashes),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def _options_hash(options: Mapping[str, Any]) -> str:
    text = json.dumps(dict(options), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _read_state(path: Path) -> dict[str, Any]:
    """The stages recorded by earlier runs, or ``{}`` (a damaged state means: rerun all)."""
    try:
        doc = load_yaml_file(path, "the run state (YAML)")
    except InputError:
        return {}
    if not isinstance(doc, dict) or doc.get("schema") != STATE_SCHEMA:
        return {}
    stages = doc.get("stages")
    return dict(stages) if isinstance(stages, dict) else {}


def _write_state(path: Path, config: RunConfig | RigRunConfig, stages: Mapping[str, Any]) -> None:
    doc = {
        "schema": STATE_SCHEMA,
        "schema_version": 1,
        "tool": {"name": "acscal", "version": acs_cli.__version__},
        "config": str(config.path),
        "stages": dict(stages),
    }
    atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False, default_flow_style=False))


def _rel(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return str(path)


def _up_to_date(record: Any, stamp: str, stage: _Stage, base: Path) -> bool:
    if not isinstance(record, dict) or record.get("stamp") != stamp:
        return False
    outputs = record.get("outputs")
    if not isinstance(outputs, dict):
        return False
    for out in stage.outputs:
        want = outputs.get(_rel(out, base))
        if not out.is_file() or want != sha256_of(out):
            return False
    return True


def _link_images(folders: Mapping[str, Path], dest: Path) -> Path:
    """A folder of links to the images of several folders (``<label>_<name>``)."""
    wanted: dict[str, Path] = {}
    for label, folder in folders.items():
        for img in list_images(folder):
            wanted[f"{label}_{img.name}"] = img.resolve()
    try:
        dest.mkdir(parents=True, exist_ok=True)
        for entry in dest.iterdir():
            if entry.name not in wanted or not (
                entry.is_symlink() and Path(os.readlink(entry)) == wanted[entry.name]
            ):
                entry.unlink()
        for name, target in wanted.items():
            link = dest / name
            if link.is_symlink() or link.exists():
                continue
            try:
                link.symlink_to(target)
            except OSError:  # no symlinks here (some file systems): copy
                shutil.copy2(target, link)
    except OSError as exc:
        raise InputError(
            f"cannot prepare the image links ({exc.strerror or exc})", path=dest
        ) from exc
    return dest


def _fmt(values: Any, digits: int = 4) -> str:
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    return "[" + ", ".join(f"{v:+.{digits}f}" for v in arr) + "]"


def _numbers(kind: str, output: Path) -> str:
    """Headline numbers of a stage's artifact (for the summary; '' if unreadable)."""
    try:
        if kind == "poses":
            with np.load(output) as z:
                n = int(np.asarray(z["T_world_cam"]).shape[0])
                rms = np.asarray(z["reprojection_rms"], dtype=float)
            return f"{n} poses, median RMS {float(np.median(rms)):.3f} px"
        doc = yaml.safe_load(output.read_text(encoding="utf-8"))
        if kind == "intrinsics":
            K = doc["camera_matrix"]
            used = len(doc["images"]["used"])
            return (
                f"RMS {doc['rms_px']:.3f} px, {used}/{doc['images']['total']} images, "
                f"fx {K[0][0]:.1f} fy {K[1][1]:.1f}"
            )
        if kind == "joint":
            j = doc["joint"]
            text = f"O_a {_fmt(j['position_in_a'])}"
            if j.get("position_in_b") is not None:
                text += f", O_b {_fmt(j['position_in_b'])}"
            return text + f" {j.get('units', 'm')}"
        if kind == "rig":
            cams, joints = doc["cameras"], doc["joints"]
            unk = [n for n, c in cams.items() if c.get("unknown_scale")]
            text = f"{len(cams)} cameras, {len(joints)} joints"
            if unk:
                text += ", scale " + ", ".join(f"{n} {float(cams[n]['scale']):.4g}" for n in unk)
            ba = doc.get("bundle_adjustment")
            if isinstance(ba, dict) and ba:
                worst = max(float(b["rms_px"]) for b in ba.values())
                text += f", bundle adjustment RMS <= {worst:.3f} px"
            return text
        if kind == "relpose":
            rel = doc["relative_pose"]
            text = (
                f"T_b_a rpy {_fmt(rel['rpy_deg'], 2)} deg, t_a_b {_fmt(rel['translation_b_in_a'])}"
            )
            scale = doc.get("scale")
            if isinstance(scale, dict) and scale.get("phi_ba") is not None:
                text += f", phi {float(scale['phi_ba']):.4f}"
            joint = doc.get("joint")
            if isinstance(joint, dict) and "self-calibrated" in str(joint.get("source")):
                text += f", O_a {_fmt(joint['position_in_a'])}"
            return text
    except (OSError, KeyError, TypeError, ValueError, IndexError, yaml.YAMLError):
        return ""
    return ""


def _poses_stage(
    stage: str,
    images: Path,
    intrinsics: Path,
    npz: Path,
    board: tuple[int, int, float],
    workers: int | None,
    times: tuple[Path | None, float | None] = (None, None),
    target: MarkerTarget | None = None,
    selection: FrameSelection = EVERY_FRAME,
    topic: str | None = None,
) -> _Stage:
    """The poses stage of one camera's image folder or video (``npz`` and the TUM file
    beside it), on the board, or on ``target`` when given (``selection``: a video's
    frames)."""
    from acs_cli.stages.poses import PosesConfig, run_poses

    cols, rows, square = board
    tum = npz.with_suffix(".tum")
    pcfg = PosesConfig(
        cols=cols if target is None else None,
        rows=rows if target is None else None,
        square=square if target is None else None,
        tum=tum,
        workers=workers,
        timestamps=times[0],
        fps=times[1],
        target=target,
        selection=selection,
        topic=topic,
    )

    def do_poses(_read: Mapping[str, PosesArtifact]) -> list[str]:
        return run_poses(images, intrinsics, npz, pcfg).warnings

    inputs = {"images": images, "intrinsics": intrinsics}
    if times[0] is not None:
        inputs["timestamps"] = times[0]
    options: dict[str, Any] = _target_options(board, target)
    if times[1] is not None:
        options["fps"] = times[1]
    options |= _selection_options(selection) | ({"topic": topic} if topic else {})
    return _Stage(stage, "poses", inputs, options, [npz, tum], do_poses)


def _selection_options(selection: FrameSelection) -> dict[str, Any]:
    """A stage's options naming a video's frame selection (none for every frame)."""
    if selection.trivial:
        return {}
    out: dict[str, Any] = {"every": selection.every, "max_frames": selection.max_frames}
    if selection.skip_blurred:
        out["skip_blurred"] = True
    if selection.min_change is not None:
        out["min_change"] = selection.min_change
    return out


def _selection(cam: CameraSpec | RigCameraSpec) -> FrameSelection:
    return FrameSelection(cam.every, cam.max_frames, cam.skip_blurred, cam.min_change)


def _target_options(board: tuple[int, int, float], target: MarkerTarget | None) -> dict[str, Any]:
    """A stage's options naming its board (``cols rows square``) or its target."""
    if target is not None:
        return {"target": target.short()}
    return {"cols": board[0], "rows": board[1], "square": board[2]}


def _plan(config: RunConfig) -> tuple[list[_Stage], dict[str, Path]]:
    """The stages of a run in order, and the intrinsics file of each camera."""
    from acs_cli.stages.intrinsics import IntrinsicsConfig, run_intrinsics
    from acs_cli.stages.joint import JointConfig, run_joint
    from acs_cli.stages.relpose import RelposeConfig, run_relpose

    out = config.output
    board = _target_options((config.cols, config.rows, config.square), config.target)
    stages: list[_Stage] = []
    intrinsics: dict[str, Path] = {}
    poses: dict[str, Path] = {}
    general: dict[str, Path] = {}
    rel = config.relpose

    for name, cam in config.cameras.items():
        cam_dir = out / f"cam_{name}"
        if config.intrinsics_from is not None:
            intrinsics[name] = config.intrinsics_from[name]
            continue
        folders: dict[str, Path] = {}
        if cam.images is not None:
            folders["joint"] = cam.images
        if rel is not None and (config.intrinsics_images == "all" or cam.images is None):
            folders["general"] = rel.images[name]
        intr_out = cam_dir / "intrinsics.yaml"
        intrinsics[name] = intr_out
        joint_only = list(folders) == ["joint"]
        selection = _selection(cam) if joint_only else EVERY_FRAME
        icfg = IntrinsicsConfig(
            cols=config.cols,
            rows=config.rows,
            square=config.square,
            model=cam.model,
            workers=config.workers,
            target=config.target,
            accept_weak=config.accept_weak,
            selection=selection,
            topic=cam.topic if joint_only else None,
        )

        def do_intrinsics(
            _read: Mapping[str, PosesArtifact],
            folders: dict[str, Path] = folders,
            cam_dir: Path = cam_dir,
            intr_out: Path = intr_out,
            icfg: IntrinsicsConfig = icfg,
        ) -> list[str]:
            if len(folders) == 1:
                images = next(iter(folders.values()))
            elif any(is_video_path(f) or is_bag_path(f) for f in folders.values()):
                raise InputError(
                    f"camera {cam_dir.name}'s intrinsics would pool a video or bag with other "
                    "images; set 'intrinsics: {from: joint}' (or give intrinsics_from)",
                    path=next(f for f in folders.values() if is_video_path(f) or is_bag_path(f)),
                )
            else:
                images = _link_images(folders, cam_dir / "intrinsics_images")
            return run_intrinsics(images, intr_out, icfg).warnings

        stages.append(
            _Stage(
                f"intrinsics {name}",
                "intrinsics",
                {f"images_{k}": v for k, v in folders.items()},
                {
                    **board,
                    "model": cam.model,
                    "images_from": sorted(folders),
                    "accept_weak": config.accept_weak,
                    **_selection_options(selection),
                    **({"topic": cam.topic} if joint_only and cam.topic else {}),
                },
                [intr_out],
                do_intrinsics,
            )
        )

    def poses_stage(
        name: str,
        images: Path,
        stem: str,
        label: str,
        selection: FrameSelection,
        topic: str | None = None,
    ) -> Path:
        npz = out / f"cam_{name}" / f"{stem}.npz"
        stages.append(
            _poses_stage(
                f"{label} {name}",
                images,
                intrinsics[name],
                npz,
                (config.cols, config.rows, config.square),
                config.workers,
                (config.cameras[name].timestamps, config.cameras[name].fps),
                config.target,
                selection,
                topic,
            )
        )
        return npz

    for name, cam in config.cameras.items():
        if config.joint is not None and cam.images is not None:
            poses[name] = poses_stage(
                name, cam.images, "poses", "poses", _selection(cam), cam.topic
            )
        if rel is not None:
            general[name] = poses_stage(
                name, rel.images[name], "poses_general", "poses general", EVERY_FRAME
            )

    joint_file: Path | None = None
    if config.joint is not None:
        jspec = config.joint
        joint_file = out / "joint.yaml"
        jcfg = JointConfig(
            scenario=jspec.scenario,
            method=jspec.method,
            bundle=jspec.bundle,
            accept_weak=config.accept_weak,
            joint_type=jspec.joint_type,
        )
        pa, pb = poses["a"], poses.get("b")
        jout = joint_file

        def do_joint(read: Mapping[str, PosesArtifact]) -> list[str]:
            return run_joint(read.get("poses_a", pa), read.get("poses_b", pb), jout, jcfg).warnings

        stages.append(
            _Stage(
                "joint",
                "joint",
                {"poses_a": pa} | ({"poses_b": pb} if pb is not None else {}),
                {
                    "scenario": jspec.scenario,
                    "method": jspec.method,
                    "bundle": jspec.bundle,
                    "accept_weak": config.accept_weak,
                }
                # a ball's options as before (a resumed run's stages stay done)
                | ({"joint_type": jspec.joint_type} if jspec.joint_type != "ball" else {}),
                [joint_file],
                do_joint,
                dict.fromkeys(["poses_a"] + (["poses_b"] if pb is not None else []), "auto"),
            )
        )

    if rel is not None:
        rcfg = RelposeConfig(
            method=rel.method,
            unknown_scale=rel.unknown_scale,
            self_calibrate=rel.self_calibrate,
            reference=rel.reference,
            bundle=rel.bundle,
            accept_weak=config.accept_weak,
            joint_type=rel.joint_type,
        )
        rout = out / "relpose.yaml"
        ga, gb = general["a"], general["b"]
        jf = joint_file

        def do_relpose(read: Mapping[str, PosesArtifact]) -> list[str]:
            pa, pb = read.get("poses_a", ga), read.get("poses_b", gb)
            return run_relpose(pa, pb, jf, rout, rcfg).warnings

        stages.append(
            _Stage(
                "relpose",
                "relpose",
                {"poses_a": ga, "poses_b": gb} | ({"joint": jf} if jf is not None else {}),
                {
                    "method": rel.method,
                    "unknown_scale": rel.unknown_scale,
                    "self_calibrate": rel.self_calibrate,
                    "reference": rel.reference,
                    "bundle": rel.bundle,
                    "accept_weak": config.accept_weak,
                }
                | ({"joint_type": rel.joint_type} if rel.joint_type != "ball" else {}),
                [rout],
                do_relpose,
                dict.fromkeys(["poses_a", "poses_b"], "auto"),
            )
        )
    return stages, intrinsics


def _sfm_stage(
    name: str,
    images: Path,
    intrinsics: Path | None,
    out: Path,
    config: RigRunConfig,
    cam_name: str | None = None,
) -> tuple[_Stage, Path]:
    """A camera's markerless poses stage (``front_end: sfm``) and the NPZ it writes
    (``name`` labels the stage; ``cam_name``, the camera, names its folder)."""
    from acs_cli.stages.poses import SfmPosesConfig, run_sfm_poses

    cam_name = cam_name or name
    npz = out / f"cam_{cam_name}" / "poses.npz"
    cam = config.cameras[cam_name]
    cfg = SfmPosesConfig(
        workers=config.workers,
        tum=npz.with_suffix(".tum"),
        timestamps=cam.timestamps,
        fps=cam.fps,
        selection=_selection(cam),
        topic=cam.topic,
        **config.sfm,
    )

    def do_sfm(_read: Mapping[str, PosesArtifact]) -> list[str]:
        return run_sfm_poses(images, intrinsics, npz, cfg).warnings

    inputs: dict[str, Path] = {"images": images}
    if intrinsics is not None:
        inputs["intrinsics"] = intrinsics
    if cam.timestamps is not None:
        inputs["timestamps"] = cam.timestamps
    options = {"front_end": "sfm", **config.sfm} | ({"fps": cam.fps} if cam.fps else {})
    options |= _selection_options(_selection(cam)) | ({"topic": cam.topic} if cam.topic else {})
    return _Stage(f"sfm {name}", "poses", inputs, options, [npz], do_sfm), npz


def _plan_rig(config: RigRunConfig) -> tuple[list[_Stage], dict[str, Path]]:
    """The stages of a rig run: intrinsics and poses of cameras with images, then the rig."""
    from acs_cli.core.joints import joint_model
    from acs_cli.io.rig_residuals import RESIDUALS_FILE
    from acs_cli.stages.rig import RIG_FILE, TRAJECTORY_DIR, label, run_rig

    stages: list[_Stage] = []
    intrinsics: dict[str, Path] = {}
    poses: dict[str, Path] = {}
    for rname, rec in config.recordings.items():
        # a config of one recording keeps its cameras' folders at the top of the output
        out = config.output if config.single else config.output / rname
        for cam_name, cam in rec.cameras.items():
            name = label(config, rname, cam_name)
            _plan_rig_camera(config, name, cam_name, cam, out, stages, intrinsics, poses)
    out = config.output
    rig_out = out / RIG_FILE
    # every camera's trajectory file (by label, with its format), by its role in the header
    files = {
        label(config, r, n): (c.poses, c.format)
        for r, rec in config.recordings.items()
        for n, c in rec.cameras.items()
        if c.poses is not None
    } | {n: (p, "npz") for n, p in poses.items()}
    role = {n: f"poses_{n.replace('/', '_')}" for n in files}
    inputs = {role[n]: p for n, (p, _) in files.items()}
    for jname, js in config.joints.items():
        inputs |= {f"fixed_joint_{jname}_{c}": p for c, p in js.fixed_joint.items()}

    def do_rig(read: Mapping[str, PosesArtifact]) -> list[str]:
        given = {n: read.get(role[n], p) for n, (p, _) in files.items()}
        return run_rig(config, given, rig_out).warnings

    traj = out / TRAJECTORY_DIR
    seen = config.recordings[config.reference_recording].cameras
    traj_files = [traj / f"{c}.tum" for c in seen]
    traj_files += [
        traj / f"{n}.tum"
        for n, j in config.joints.items()
        if joint_model(j.type).has_point and all(b in seen for b in j.between)
    ]

    stages.append(
        _Stage(
            "rig",
            "rig",
            inputs | {"config": config.path},
            {
                "reference": [
                    config.reference_camera,
                    config.reference_frame,
                    config.reference_recording,
                ],
                "accept_weak": config.accept_weak,
            },
            [rig_out, *traj_files, out / RESIDUALS_FILE],
            do_rig,
            {role[n]: fmt for n, (_, fmt) in files.items()},
        )
    )
    return stages, intrinsics


def _plan_rig_camera(
    config: RigRunConfig,
    name: str,
    cam_name: str,
    cam: RigCameraSpec,
    out: Path,
    stages: list[_Stage],
    intrinsics: dict[str, Path],
    poses: dict[str, Path],
) -> None:
    """The intrinsics and poses stages (or the sfm stage) of one camera of one recording,
    labelled ``name``, its files in ``out/cam_<camera>``."""
    from acs_cli.stages.intrinsics import IntrinsicsConfig, run_intrinsics

    if cam.images is not None and cam.front_end == "sfm":
        stage, poses[name] = _sfm_stage(name, cam.images, cam.intrinsics, out, config, cam_name)
        stages.append(stage)
        return
    if cam.images is None or (config.board is None and config.target is None):
        return
    defaults = IntrinsicsConfig()  # the board's fields, unused with a target
    the_board = config.board or (defaults.cols, defaults.rows, defaults.square)
    cols, rows, square = the_board
    board = _target_options(the_board, config.target)
    cam_dir = out / f"cam_{cam_name}"
    intr_out = cam_dir / "intrinsics.yaml"
    intrinsics[name] = intr_out
    icfg = IntrinsicsConfig(
        cols=cols,
        rows=rows,
        square=square,
        model=cam.model,
        workers=config.workers,
        target=config.target,
        accept_weak=config.accept_weak,
        selection=_selection(cam),
        topic=cam.topic,
    )
    images = cam.images

    def do_intrinsics(
        _read: Mapping[str, PosesArtifact],
        images: Path = images,
        intr_out: Path = intr_out,
        icfg: IntrinsicsConfig = icfg,
    ) -> list[str]:
        return run_intrinsics(images, intr_out, icfg).warnings

    stages.append(
        _Stage(
            f"intrinsics {name}",
            "intrinsics",
            {"images": images},
            {
                **board,
                "model": cam.model,
                "accept_weak": config.accept_weak,
                **_selection_options(_selection(cam)),
                **({"topic": cam.topic} if cam.topic else {}),
            },
            [intr_out],
            do_intrinsics,
        )
    )
    npz = cam_dir / "poses.npz"
    stages.append(
        _poses_stage(
            f"poses {name}",
            images,
            intr_out,
            npz,
            the_board,
            config.workers,
            (cam.timestamps, cam.fps),
            config.target,
            _selection(cam),
            cam.topic,
        )
    )
    poses[name] = npz


def run_pipeline(
    config: RunConfig | RigRunConfig,
    *,
    force: bool = False,
    only: str | None = None,
    on_stage: StageCallback | None = None,
) -> PipelineRun:
    """Run the configured stages, skipping those whose inputs and options are unchanged.

    Parameters
    ----------
    config : RunConfig
        From :func:`load_run_config`.
    force : bool
        Run every (selected) stage even if it is up to date.
    only : str, optional
        Run only the stages of this kind (one of :data:`STAGE_KINDS`); the others' outputs
        must exist already.
    on_stage : callable, optional
        Called with each :class:`StageResult` as soon as the stage is done.

    Raises
    ------
    InputError
        Bad inputs (from the stages), or ``--only`` with an upstream output missing.
    DegenerateMotionError
        A stage's motion cannot determine its answer; the stages before it are recorded.
    """
    if only is not None and only not in STAGE_KINDS:
        raise InputError(f"--only must be one of {', '.join(STAGE_KINDS)}, got {only!r}")
    t0 = time.perf_counter()
    out = config.output
    state_file = out / STATE_FILE
    state = _read_state(state_file)
    if isinstance(config, RigRunConfig):
        stages, intrinsics = _plan_rig(config)
    else:
        stages, intrinsics = _plan(config)
    results: list[StageResult] = []

    def report(res: StageResult) -> None:
        results.append(res)
        if on_stage is not None:
            on_stage(res)

    if not isinstance(config, RigRunConfig) and config.intrinsics_from is not None:
        for name, path in intrinsics.items():
            if not path.is_file():
                raise InputError(
                    f"no such intrinsics file (key 'intrinsics_from' of {config.path})",
                    path=path,
                )
            report(
                StageResult(f"intrinsics {name}", "reused", [path], _numbers("intrinsics", path))
            )

    if only is not None and not any(s.kind == only for s in stages):
        raise InputError(f"--only {only}: the config runs no {only} stage", path=config.path)
    for stage in stages:
        if only is not None and stage.kind != only:
            upstream = STAGE_KINDS.index(stage.kind) < STAGE_KINDS.index(only)
            missing = [p for p in stage.outputs if upstream and not p.is_file()]
            if missing:
                raise InputError(
                    f"--only {only}: the {stage.stage} stage has not run yet; run without "
                    "--only first",
                    path=missing[0],
                )
            report(StageResult(stage.stage, "not selected", stage.outputs))
            continue
        read = {}  # a file that cannot be read is left to the stage: it says why, in its words
        for role, fmt in stage.poses.items():
            with contextlib.suppress(InputError):
                read[role] = PosesArtifact.load(stage.inputs[role], fmt)
        # the output folder may lie inside an image folder: its files are not inputs
        hashes = {
            role: (read[role].sha256 if role in read else None) or sha256_of(p, exclude=[out])
            for role, p in stage.inputs.items()
        }
        stamp = _stamp(stage, hashes)
        if not force and _up_to_date(state.get(stage.stage), stamp, stage, out):
            report(
                StageResult(
                    stage.stage, "skipped", stage.outputs, _numbers(stage.kind, stage.outputs[0])
                )
            )
            continue
        ts = time.perf_counter()
        try:
            warnings = stage.action(read)
        except DegenerateMotionError as exc:  # the report shows what ran, and why this failed
            if out.is_dir() and any(out.iterdir()):
                write_run_report(out, report, [f"{stage.stage} failed: {exc.one_line()}"])
            raise
        state[stage.stage] = {
            "stamp": stamp,
            "options_sha256": _options_hash(stage.options),
            "options": stage.options,
            "inputs": {
                role: {"path": str(p), "sha256": hashes[role]} for role, p in stage.inputs.items()
            },
            "outputs": {_rel(p, out): sha256_of(p) for p in stage.outputs},
        }
        _write_state(state_file, config, state)
        report(
            StageResult(
                stage.stage,
                "ran",
                stage.outputs,
                _numbers(stage.kind, stage.outputs[0]),
                time.perf_counter() - ts,
                list(warnings),
            )
        )
    write_run_report(out, report)
    return PipelineRun(config, results, state_file, time.perf_counter() - t0)


def write_run_report(
    out: Path, on_stage: StageCallback | None = None, failures: list[str] | None = None
) -> StageResult:
    """Write ``out/report.html`` (and its figures) from whatever the run folder holds.

    Always regenerated, even when every stage was skipped: it is cheap, reads only the
    artifacts and is not recorded in the state file. Its status is ``written`` (or
    ``failed``, with the reason as a warning: a report never fails a run).
    """
    from acs_cli.stages.report import ReportConfig, run_report

    ts = time.perf_counter()
    path = out / REPORT_FILE
    try:
        rep = run_report(out, path, ReportConfig(extra_warnings=tuple(failures or ())))
        res = StageResult("report", "written", [path], f"{len(rep.figures)} figures")
    except AcsError as exc:
        res = StageResult("report", "failed", [path], warnings=[exc.one_line()])
    res.seconds = time.perf_counter() - ts
    if on_stage is not None:
        on_stage(res)
    return res
