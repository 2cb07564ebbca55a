"""Calibrate a rig from arrays of poses with acscal's Python API (docs/python_api.md).

Part 1: a simulated arm of four cameras (a ball, a hinge and a rigid joint), each camera's
trajectory in its own world, one of unknown scale; solved by ``estimate_rig``, every joint
printed with its std beside the truth, and ``rig.yaml`` written through the typed artifact.
Part 2: a leg seen by motion capture in two recordings (a hip trial and a knee trial), each
recording's bodies in one lab world (``world: shared``).

    python examples/calibrate_rig_from_arrays.py [--out DIR] [--seed N]
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from acs_cli.core.rig import rig_topology
from acs_cli.core.rig_solve import CameraTrack, Recordings, estimate_rig
from acs_cli.errors import DegenerateMotionError
from acs_cli.io.artifacts import make_header
from acs_cli.io.rig import RigArtifact
from acs_cli.stages.rig import rig_artifact
from sample_data_gen import mocap_sim
from sample_data_gen.rig_sim import rig_recording

ARM = (
    ("shoulder", ("base", "upper"), "ball"),
    ("elbow", ("upper", "fore"), "hinge"),
    ("wrist", ("fore", "hand"), "rigid"),
)


def vec(v: np.ndarray) -> str:
    return "[" + " ".join(f"{x:+.4f}" for x in v) + "]"


def angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    """The angle between two axes (either sign), degrees."""
    return float(np.degrees(np.arccos(min(1.0, abs(float(u @ v))))))


def part1(rng: np.random.Generator, out: Path) -> None:
    print("== part 1: a four-camera arm, one recording, a world per camera ==")
    # sim.T_wc_c[c]: (n, 4, 4) T_world_cam of camera c in its own world (a TUM file's poses)
    sim = rig_recording(rng, 80, joints=ARM, reference="base", unknown_scale=("hand",),
                        sigma_rot_deg=0.2, sigma_trans=0.002)  # fmt: skip
    n = sim.timestamps.size
    topology = rig_topology(["base", "upper", "fore", "hand"], ARM, reference="base")
    tracks = {
        c: CameraTrack(sim.T_wc_c[c], np.ones(n, bool), unknown_scale=sim.unknown_scale[c])
        for c in topology.cameras
    }
    est = estimate_rig(topology, tracks, reference_frame=0)

    for name, e in est.edges.items():
        truth, (p, q) = sim.edges[name], e.joint.between
        print(f"joint {name} ({e.joint.type}, {p}-{q}): {e.frames_used} frames used")
        if e.joint.type == "rigid":  # T_q_p maps p's frame into q's
            t_true = np.linalg.inv(truth.T_p_q(np.eye(3)[None])[0])[:3, 3]
            print(f"  T_{q}_{p} translation {vec(e.T_q_p[:3, 3])} m  true {vec(t_true)}")
            continue
        for c, o_true in ((p, truth.o_p), (q, truth.o_q)):
            std = np.sqrt(np.diag(e.position_cov_in[c]))  # from the (3, 3) covariance, m^2
            print(f"  position in {c:5s} {vec(e.position_in[c])} m  std {vec(std)}  "
                  f"true {vec(o_true)}")  # fmt: skip
        for c, u_true in ((p, truth.axis_p), (q, truth.axis_q)):
            if c in e.axis_in and u_true is not None:
                err = angle_deg(e.axis_in[c], u_true)
                print(f"  axis in {c:5s} {vec(e.axis_in[c])}  std {e.axis_std_deg_in[c]:.3f} "
                      f"deg  error {err:.3f} deg")  # fmt: skip
    truth_T = sim.T_cam_ref(0)
    for c, cam in est.cameras.items():
        assert cam.T_cam_ref is not None
        t_err = np.linalg.norm(cam.T_cam_ref[:3, 3] - truth_T[c][:3, 3])
        line = (f"camera {c:5s} t_cam_ref {vec(cam.T_cam_ref[:3, 3])} m  "
                f"std {vec(cam.translation_std)}  error {t_err:.4f} m")  # fmt: skip
        if cam.scale_std is not None:
            line += f"  scale {cam.scale:.4f} +- {cam.scale_std:.4f} (true {sim.scale()[c]:.4f})"
        print(line)

    # rig.yaml through the typed artifact: rig_artifact, a header, save; load reads it back
    art = rig_artifact(est, "m", est.warnings)
    header = make_header("rig", {}, "estimate_rig from arrays (examples/)", {"length": "m"}, {})
    path = out / "rig.yaml"
    dataclasses.replace(art, header=header).save(path)
    back = RigArtifact.load(path)
    T = back.T_a_b("hand", "upper")  # maps upper's frame into hand's, at the reference instant
    T_true = truth_T["hand"] @ np.linalg.inv(truth_T["upper"])
    print(f"wrote {path}; T_hand_upper translation {vec(T[:3, 3])} m (true {vec(T_true[:3, 3])})")
    print(back.summary())

    # motion that cannot determine the answer raises DegenerateMotionError (exit 3 in the CLI)
    few = {c: CameraTrack(t.T_w_c[:10], t.valid[:10], t.unknown_scale) for c, t in tracks.items()}
    try:
        estimate_rig(topology, few)
    except DegenerateMotionError as exc:
        print(f"10 frames refused (DegenerateMotionError): {exc.message.split(';')[0]}")


def part2(rng: np.random.Generator) -> None:
    print("== part 2: a leg, two recordings, each in one shared lab world ==")
    hip, knee = mocap_sim.hip_trial(rng, n=150), mocap_sim.knee_trial(rng, n=150)
    leg = rig_topology(
        ["pelvis", "femur", "tibia"],
        [("hip", ["pelvis", "femur"], "ball"), ("knee", ["femur", "tibia"], "hinge")],
        reference="pelvis",
    )
    # one timeline: the hip trial's 150 instants, then the knee trial's; a body a recording
    # does not see has identity rows there, marked invalid
    tracks = {}
    for body in leg.cameras:
        T = np.broadcast_to(np.eye(4), (300, 4, 4)).copy()
        valid = np.zeros(300, bool)
        for at, trial in ((0, hip), (150, knee)):
            if body in trial.measured:  # T_lab_segment, (150, 4, 4)
                T[at : at + 150], valid[at : at + 150] = trial.measured[body], True
        tracks[body] = CameraTrack(T, valid)
    recordings = Recordings(("hip", "knee"), np.repeat([0, 1], 150), shared_world=(True, True))
    est = estimate_rig(leg, tracks, reference_frame=0, recordings=recordings)
    hip_e, knee_e = est.edges["hip"], est.edges["knee"]
    std = np.sqrt(np.diag(hip_e.position_cov_in["pelvis"]))
    print(f"hip centre in pelvis {vec(hip_e.position_in['pelvis'])} m  std {vec(std)}  "
          f"true {vec(mocap_sim.HIP_IN_PELVIS)}")  # fmt: skip
    u = knee_e.axis_in["femur"]
    err = angle_deg(u, mocap_sim.KNEE_AXIS_IN_FEMUR)
    print(f"knee axis in femur {vec(u)}  std {knee_e.axis_std_deg_in['femur']:.3f} deg  "
          f"error {err:.3f} deg")  # fmt: skip
    for w in est.worlds:
        print(f"world {w.label}: bodies {', '.join(w.cameras)}, tied to the reference: {w.tied}")
    print(f"tibia T_cam_ref: {est.cameras['tibia'].T_cam_ref} (not in the reference recording)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="folder for rig.yaml (default: a temporary one)")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        part1(rng, out)
        part2(rng)


if __name__ == "__main__":
    main()
