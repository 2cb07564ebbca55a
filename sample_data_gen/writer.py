"""Write synthetic ACS recordings: two TUM trajectories and the ground truth.

A scenario folder holds

- ``cam_a.tum``, ``cam_b.tum``: ``T_world_cam`` of camera A (world A) and camera B
  (world B), timestamps from the sequence; translations in ``mu_a`` (``mu_b``) x metres;
- ``truth.yaml``: an ``acscal/truth`` artifact with the joint, the relative pose at the
  reference instant 0, the world-to-world transform, the scales, the noise and the seed.

Randomness is split so that one seed gives one rig whatever the scenario: the rig comes
from ``default_rng([seed, 0])`` and a scenario's motion and noise from
``default_rng([seed, 1, k])`` (``k`` the scenario's index in :data:`SCENARIOS`). So the
three scenarios written for one seed share a rig (a joint calibrated on ``fixed_joint``
feeds ``relpose`` on ``general``), and a scaled scenario is its unscaled twin's noisy poses
with the translations scaled.

:func:`write_rig_recording` writes a rig of many cameras instead
(:mod:`sample_data_gen.rig_sim`, randomness from ``default_rng([seed, 2])``): one TUM file
per camera, its ``truth.yaml`` (``acscal/rig_truth``) and a run config ``config.yaml``
(version 2) naming the cameras and joints.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from acs_cli.core import se3
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.atomic import atomic_write_text
from acs_cli.io.trajectory import write_tum
from sample_data_gen.acs_sim import (
    Sequence,
    SyntheticRig,
    add_pose_noise,
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
)
from sample_data_gen.rig_sim import CornerRecording, RigRecording, rig_recording

__all__ = [
    "RIG_NOISE",
    "RIG_UNKNOWN_SCALE",
    "SAMPLE_MU_A",
    "SAMPLE_MU_B",
    "SCENARIOS",
    "make_sequence",
    "rig_config_text",
    "rig_for_seed",
    "rig_truth_body",
    "write_rig_recording",
    "write_sample_set",
    "write_scenario",
]

#: Scenarios :func:`write_scenario` knows: Algorithm II, Algorithm I, Algorithms III/IV.
SCENARIOS = ("fixed_joint", "overlap", "general")
#: Scales of the ``*_scaled`` sample scenarios (the paper's section 6.4).
SAMPLE_MU_A = 0.8
SAMPLE_MU_B = 3.2

_TRUTH_KIND = "truth"
_RIG_TRUTH_KIND = "rig_truth"
#: Pose noise of the sample rig: per axis, degrees and metres.
RIG_NOISE = (0.3, 0.01)
#: Cameras of the sample rig whose trajectory has an unknown scale.
RIG_UNKNOWN_SCALE = ("cam4",)


def rig_for_seed(seed: int, hinge: bool = False) -> SyntheticRig:
    """The rig every scenario written with ``seed`` uses (``|o_a|, |o_b|`` in [1, 2] m)."""
    return make_rig(np.random.default_rng([seed, 0]), hinge=hinge)


def make_sequence(
    rng: np.random.Generator, rig: SyntheticRig, scenario: str, frames: int
) -> Sequence:
    """True motion of ``rig`` for ``scenario`` (one of :data:`SCENARIOS`), ``frames`` poses."""
    if scenario == "fixed_joint":
        return fixed_joint_sequence(rng, rig, frames)
    if scenario == "overlap":
        return general_sequence(rng, rig, frames, shared_world=True)
    if scenario == "general":
        return general_sequence(rng, rig, frames)
    raise ValueError(f"unknown scenario {scenario!r}; choose one of {', '.join(SCENARIOS)}")


def _truth_body(
    scenario: str,
    rig: SyntheticRig,
    seq: Sequence,
    *,
    seed: int,
    frames: int,
    rot_noise_deg: float,
    trans_noise: float,
    mu_a: float,
    mu_b: float,
) -> dict[str, Any]:
    T_b_a = seq.T_b_a(0)
    T_a_b = se3.invert_transforms(T_b_a)
    joint: dict[str, Any] = {
        "position_in_a": rig.o_a,
        "position_in_b": rig.o_b,
    }
    if seq.joint_in_world_a is not None:
        p_wa = np.asarray(seq.joint_in_world_a, dtype=float)
        joint["position_in_world_a"] = p_wa
        joint["position_in_world_b"] = se3.transform_points(seq.T_wb_wa, p_wa)
    return {
        "scenario": scenario,
        "seed": int(seed),
        "n_frames": int(frames),
        "files": {"cam_a": "cam_a.tum", "cam_b": "cam_b.tum"},
        "joint": joint,
        "hinge_axis_in_a": rig.hinge_axis_a,
        "relative_pose": {
            "reference": 0,
            "T_b_a": T_b_a,
            "rpy_deg": se3.rpy_deg_from_matrix(T_a_b[:3, :3]),
            "translation_b_in_a": T_a_b[:3, 3],
        },
        "T_wb_wa": seq.T_wb_wa,
        "scale": {"mu_a": float(mu_a), "mu_b": float(mu_b), "phi_ba": float(mu_b / mu_a)},
        "noise": {
            "sigma_rot_deg": float(rot_noise_deg),
            "sigma_trans": float(trans_noise),
            "model": "T_world_cam = [R Exp(n_r), t + n_t] on every pose, n_r ~ N(0, sigma_rot^2 I) "
            "(per axis, body frame), n_t ~ N(0, sigma_trans^2 I) in metres, added before the "
            "translations are scaled by mu",
        },
    }


def _write(
    out_dir: Path,
    scenario: str,
    rig: SyntheticRig,
    *,
    seed: int,
    frames: int,
    rot_noise_deg: float,
    trans_noise: float,
    mu_a: float,
    mu_b: float,
) -> Path:
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; choose one of {', '.join(SCENARIOS)}")
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    if rot_noise_deg < 0 or trans_noise < 0:
        raise ValueError("noise levels must not be negative")
    if not (mu_a > 0 and mu_b > 0):
        raise ValueError(f"scales must be positive, got mu_a={mu_a}, mu_b={mu_b}")
    rng = np.random.default_rng([seed, 1, SCENARIOS.index(scenario)])
    seq = make_sequence(rng, rig, scenario, frames)
    T_a = add_pose_noise(rng, seq.T_wa_a, rot_noise_deg, trans_noise)
    T_b = add_pose_noise(rng, seq.T_wb_b, rot_noise_deg, trans_noise)
    T_a = scale_translations(T_a, mu_a)
    T_b = scale_translations(T_b, mu_b)
    out = Path(out_dir)
    write_tum(out / "cam_a.tum", seq.timestamps, T_a)
    write_tum(out / "cam_b.tum", seq.timestamps, T_b)
    header = make_header(
        _TRUTH_KIND,
        inputs={},
        method=(
            f"synthetic ACS (sample_data_gen, Chen & Wong section 5): scenario {scenario}, "
            f"seed {seed}, {frames} frames"
        ),
        units={
            "length": "metres (joint, relative_pose, T_wb_wa, noise.sigma_trans)",
            "angles": "deg",
            "cam_a.tum": "mu_a x metres",
            "cam_b.tum": "mu_b x metres",
        },
        frames={
            "joint.position_in_a": "a",
            "joint.position_in_b": "b",
            "joint.position_in_world_a": "world_a",
            "joint.position_in_world_b": "world_b",
            "hinge_axis_in_a": "a",
            "relative_pose.T_b_a": "maps a to b at the reference instant (paper's H_BA)",
            "relative_pose.rpy_deg": "of R_a_b (paper's ~R_BA)",
            "relative_pose.translation_b_in_a": "t_a_b (paper's ~T_BA)",
            "T_wb_wa": "maps world_a to world_b (metres)",
        },
    )
    body = _truth_body(
        scenario,
        rig,
        seq,
        seed=seed,
        frames=frames,
        rot_noise_deg=rot_noise_deg,
        trans_noise=trans_noise,
        mu_a=mu_a,
        mu_b=mu_b,
    )
    write_yaml_artifact(out / "truth.yaml", header, body)
    return out


def write_scenario(
    out_dir: str | Path,
    scenario: str,
    *,
    seed: int,
    frames: int = 30,
    rot_noise_deg: float = 0.0,
    trans_noise: float = 0.0,
    mu_a: float = 1.0,
    mu_b: float = 1.0,
    hinge: bool = False,
) -> Path:
    """Write one synthetic recording into ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Folder to write ``cam_a.tum``, ``cam_b.tum`` and ``truth.yaml`` into (created).
    scenario : {"fixed_joint", "overlap", "general"}
        The motion: the joint fixed in the world (Algorithm II), general motion in one
        shared world (Algorithm I) or in two unrelated worlds (Algorithms III and IV).
    seed : int
        Fixes the rig (shared by every scenario of the seed), the motion and the noise.
    frames : int
        Poses per camera.
    rot_noise_deg, trans_noise : float
        Pose noise, per axis (degrees; metres before scaling), on every pose.
    mu_a, mu_b : float
        Unknown scales: the written translations are ``mu x`` the noisy metric ones.
    hinge : bool
        A one-axis (hinge) joint instead of a ball joint.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    ValueError
        Unknown scenario, fewer than one frame, negative noise, non-positive scale.
    """
    return _write(
        Path(out_dir),
        scenario,
        rig_for_seed(seed, hinge),
        seed=seed,
        frames=frames,
        rot_noise_deg=rot_noise_deg,
        trans_noise=trans_noise,
        mu_a=mu_a,
        mu_b=mu_b,
    )


def write_sample_set(
    out_dir: str | Path,
    seed: int = 0,
    frames: int = 30,
    rot_noise_deg: float = 0.6,
    trans_noise: float = 0.025,
) -> dict[str, Path]:
    """Write one rig's recordings: every scenario, plus two with unknown scales.

    Folders under ``out_dir``: ``fixed_joint``, ``overlap``, ``general`` (one rig, so the
    joint from ``fixed_joint`` serves ``relpose`` on ``general``), and ``general_scaled`` and
    ``fixed_joint_scaled`` (the same noisy poses with ``mu_a = 0.8``, ``mu_b = 3.2``).

    Returns
    -------
    dict of str to Path
        Each folder by name.
    """
    out = Path(out_dir)
    common: dict[str, Any] = {
        "seed": seed,
        "frames": frames,
        "rot_noise_deg": rot_noise_deg,
        "trans_noise": trans_noise,
    }
    written: dict[str, Path] = {}
    for scenario in SCENARIOS:
        written[scenario] = write_scenario(out / scenario, scenario, **common)
    for scenario in ("general", "fixed_joint"):
        name = f"{scenario}_scaled"
        written[name] = write_scenario(
            out / name, scenario, mu_a=SAMPLE_MU_A, mu_b=SAMPLE_MU_B, **common
        )
    return written


def rig_truth_body(
    rec: RigRecording, *, seed: int, rot_noise_deg: float, trans_noise: float
) -> dict[str, Any]:
    """The body of a rig's ``truth.yaml`` (see :func:`write_rig_recording`)."""
    topo = rec.topology
    T_cam_ref = rec.T_cam_ref(0)
    scale = rec.scale()
    cameras = {
        c: {
            "poses": f"{c}.tum",
            "T_cam_ref": T_cam_ref[c],
            "unknown_scale": bool(rec.unknown_scale[c]),
            "mu": float(rec.mu[c]),
            "scale": float(scale[c]),
        }
        for c in topo.cameras
    }
    joints: dict[str, Any] = {}
    for j in topo.joints:
        e = rec.edges[j.name]
        p, q = e.between
        d: dict[str, Any] = {"type": e.type, "between": [p, q]}
        if e.type != "rigid":
            d["position_in"] = {p: e.o_p, q: e.o_q}
        if e.type == "hinge":
            d["axis_in"] = {p: e.axis_p, q: e.axis_q}
        d["T_q_p"] = T_cam_ref[q] @ se3.invert_transforms(T_cam_ref[p])
        joints[j.name] = d
    return {
        "scenario": "rig",
        "seed": int(seed),
        "n_frames": len(rec.timestamps),
        "reference": {"camera": topo.reference, "frame": 0},
        "length_unit": "m",
        "cameras": cameras,
        "joints": joints,
        "noise": {
            "sigma_rot_deg": float(rot_noise_deg),
            "sigma_trans": float(trans_noise),
            "model": "T_world_cam = [R Exp(n_r), t + n_t] on every pose, n_r ~ N(0, sigma_rot^2 I) "
            "(per axis, body frame), n_t ~ N(0, sigma_trans^2 I) in metres, added before the "
            "translations are scaled by mu",
        },
    }


def rig_config_text(rec: RigRecording) -> str:
    """``config.yaml``: the run config (version 2) of the written rig, paths relative."""
    topo = rec.topology
    cameras: dict[str, Any] = {}
    for c in topo.cameras:
        cameras[c] = {"poses": f"{c}.tum"}
        if rec.unknown_scale[c]:
            cameras[c]["scale"] = "unknown"
    doc = {
        "schema": "acscal/run-config",
        "schema_version": 2,
        "output": "out/",
        "reference": {"camera": topo.reference, "frame": 0},
        "cameras": cameras,
        "joints": {j.name: {"between": list(j.between), "type": j.type} for j in topo.joints},
    }
    head = (
        "# acscal run config.yaml: the synthetic rig written by `python -m sample_data_gen OUT "
        "--rig`\n"
        "# (truth in truth.yaml); see configs/rig.yaml for every key.\n"
    )
    return head + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


def write_rig_recording(
    out_dir: str | Path,
    *,
    seed: int = 0,
    frames: int = 100,
    rot_noise_deg: float = RIG_NOISE[0],
    trans_noise: float = RIG_NOISE[1],
    unknown_scale: tuple[str, ...] = RIG_UNKNOWN_SCALE,
) -> RigRecording:
    """Write the sample rig of five cameras (:data:`sample_data_gen.rig_sim.SAMPLE_JOINTS`).

    ``cam0 -(rigid r01)- cam1``, ``cam0 -(ball j02)- cam2 -(hinge j23)- cam3 -(rigid r34)-
    cam4``, general motion; the reference camera is ``cam0`` at frame 0. ``out_dir`` gets:

    - ``cam0.tum`` .. ``cam4.tum``: each camera's ``T_world_cam`` in its own world,
      timestamps ``frame / 30`` s, noisy; translations in ``mu`` x metres (``mu`` in
      [0.3, 3] for a camera in ``unknown_scale``, else 1).
    - ``truth.yaml`` (``acscal/rig_truth``), metres: ``reference`` (``camera``,
      ``frame``), ``length_unit`` (``m``), ``cameras.<c>`` (``poses`` file, ``T_cam_ref``
      4x4 at frame 0 (maps the reference camera's frame into ``c``'s), ``unknown_scale``,
      ``mu`` (trajectory units per metre), ``scale`` (reference units per trajectory unit:
      ``mu_ref / mu_c``, as ``rig.yaml``'s)), ``joints.<j>`` (``type``, ``between: [p,
      q]``, ``position_in: {p, q}`` (ball centre or hinge point, in each camera's frame),
      ``axis_in: {p, q}`` (hinge, unit), ``T_q_p`` at frame 0), ``noise``, ``seed``,
      ``n_frames``. Keys are laid out as in ``rig.yaml``, so the two compare key by key.
    - ``config.yaml``: the run config (``schema_version: 2``) of these files (relative
      paths, output ``out/``).

    Parameters
    ----------
    out_dir : str or Path
        Folder (created).
    seed : int
        Fixes the rig, the motion and the noise (``default_rng([seed, 2])``).
    frames : int
        Poses per camera.
    rot_noise_deg, trans_noise : float
        Pose noise per axis (degrees; metres, before scaling), on every pose.
    unknown_scale : tuple of str
        Cameras whose trajectory has an unknown scale.

    Returns
    -------
    RigRecording
        The recording written (truth and trajectories).

    Raises
    ------
    ValueError
        Fewer than one frame, negative noise.
    """
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    if rot_noise_deg < 0 or trans_noise < 0:
        raise ValueError("noise levels must not be negative")
    rng = np.random.default_rng([seed, 2])
    rec = rig_recording(
        rng,
        frames,
        unknown_scale=unknown_scale,
        sigma_rot_deg=rot_noise_deg,
        sigma_trans=trans_noise,
    )
    out = Path(out_dir)
    for c in rec.topology.cameras:
        write_tum(out / f"{c}.tum", rec.timestamps, rec.T_wc_c[c])
    units: dict[str, Any] = {"length": "metres", "angles": "deg"}
    units.update({f"{c}.tum": "mu x metres" if rec.unknown_scale[c] else "metres" for c in rec.mu})
    header = make_header(
        _RIG_TRUTH_KIND,
        inputs={},
        method=(
            f"synthetic rig (sample_data_gen.rig_sim): {len(rec.mu)} cameras, seed {seed}, "
            f"{frames} frames, general motion"
        ),
        units=units,
        frames={
            "cameras.<c>.T_cam_ref": "maps the reference camera's frame (frame 0) into c's",
            "joints.<j>.position_in.<c>": "c",
            "joints.<j>.axis_in.<c>": "c",
            "joints.<j>.T_q_p": "maps p's frame into q's at frame 0",
        },
    )
    body = rig_truth_body(rec, seed=seed, rot_noise_deg=rot_noise_deg, trans_noise=trans_noise)
    write_yaml_artifact(out / "truth.yaml", header, body)
    atomic_write_text(out / "config.yaml", rig_config_text(rec))
    return rec


def write_corner_poses(
    out_dir: str | Path, rec: CornerRecording, drop: dict[str, list[int]] | None = None
) -> dict[str, Path]:
    """Write each camera of a board-camera rig (:func:`~sample_data_gen.rig_sim.
    rig_corner_recording`) as ``acscal poses`` would: ``<camera>.npz`` (its PnP poses with
    their corners, at the frames where it sees its board, timestamps ``frame / 30`` s) and
    ``<camera>_intrinsics.yaml`` (the initial intrinsics the poses were solved with, 640x480,
    pinhole), which the NPZ names by its absolute path.

    Parameters
    ----------
    out_dir : str or Path
        Folder (existing).
    rec : CornerRecording
    drop : dict of camera to list of int, optional
        Frames left out of a camera's file as well (so that rows and instants differ).

    Returns
    -------
    dict of camera to Path
        The NPZ files.
    """
    import dataclasses

    from acs_cli.io.intrinsics import IntrinsicsArtifact
    from acs_cli.io.poses import PosesArtifact
    from acs_cli.io.trajectory import Trajectory

    out_dir = Path(out_dir)
    out = {}
    for c in rec.rig.topology.cameras:
        seen = rec.valid[c].all(axis=1)
        seen[list((drop or {}).get(c, []))] = False
        i0 = rec.intrinsics0[c]
        K = np.array([[i0[0], 0.0, i0[2]], [0.0, i0[1], i0[3]], [0.0, 0.0, 1.0]])
        intr = IntrinsicsArtifact(
            model="pinhole", image_size=(640, 480), camera_matrix=K, distortion=i0[4:]
        )
        intr_file = (out_dir / f"{c}_intrinsics.yaml").resolve()
        header = make_header("intrinsics", {}, "sample_data_gen (initial intrinsics)", {}, {})
        dataclasses.replace(intr, header=header).save(intr_file)
        idx = np.flatnonzero(seen)
        art = PosesArtifact(
            trajectory=Trajectory(idx / 30.0, rec.T_board_cam[c][idx], "x", "npz", True),
            corners=rec.corners[c][idx],
            board_points=rec.board_points,
            header=make_header("poses", {}, "sample_data_gen (PnP poses)", {}, {})
            | {"intrinsics_file": str(intr_file)},
        )
        out[c] = out_dir / f"{c}.npz"
        art.save(out[c])
    return out
