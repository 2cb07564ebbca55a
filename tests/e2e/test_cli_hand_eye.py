"""Eye-in-hand calibration with `acscal run` (issue 19, item 3) on real data: a camera on a
KUKA robot's flange photographing a 28x17 board (rwhe_kuka1), the robot's poses as a TUM
file. The rig's bundle adjustment takes the flange as a body with poses only: rig.yaml
gives the hand-eye transform X (the rigid joint's T_q_p) with its std, and the board in
the robot's base (Z) with its std; writing the joint the other way round gives the same X."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.rig import RigArtifact

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "rwhe_kuka1"

pytestmark = pytest.mark.skipif(
    not (DATA / "RobotPosesVec.txt").is_file(), reason=f"rwhe_kuka1 data not found at {DATA}"
)

CONFIG = """schema: acscal/run-config
schema_version: 2
output: {out}
board: {{cols: 28, rows: 17, square: 0.020}}
pair_by: index
reference: {{camera: cam, frame: 0}}
cameras:
  cam: {{images: {images}}}
  flange: {{poses: flange.tum}}
joints:
  handeye: {{between: [{between}], type: rigid}}
"""


def _flange_tum(path: Path) -> None:
    """The robot's poses (row-major 4x4, metres: T_base_flange) as TUM rows, one per image."""
    M = np.loadtxt(DATA / "RobotPosesVec.txt").reshape(-1, 4, 4)
    q = se3.quat_xyzw_from_matrix(M[:, :3, :3])
    rows = [
        f"{i + 1} " + " ".join(f"{v:.9f}" for v in (*T[:3, 3], *qq))
        for i, (T, qq) in enumerate(zip(M, q, strict=True))
    ]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def _run(tmp: Path, between: str, out: str) -> RigArtifact:
    cfg = tmp / f"{out}.yaml"
    cfg.write_text(CONFIG.format(out=out, images=DATA, between=between), encoding="utf-8")
    res = acscal("run", cfg, cwd=tmp, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    return RigArtifact.load(tmp / out / "rig.yaml")


def test_eye_in_hand_on_a_kuka_robot(tmp_path: Path) -> None:
    _flange_tum(tmp_path / "flange.tum")
    rig = _run(tmp_path, "cam, flange", "out")
    j = rig.joints["handeye"]
    assert j.T_q_p is not None and j.T_q_p_std is not None
    # X = T_flange_cam: the camera some 10-30 cm from the flange, known to a millimetre
    assert 0.1 < np.linalg.norm(j.T_q_p[:3, 3]) < 0.4
    assert np.all(j.T_q_p_std[1] < 2e-3) and np.all(j.T_q_p_std[0] < 0.1)
    po = rig.cameras["flange"].pose_only
    assert po is not None and po.frames == 30
    # the robot's pose noise: sub-millimetre, a small fraction of a degree
    assert 0 < po.sigma_translation < 2e-3 and 0 < po.sigma_rotation_deg < 0.2
    Z = po.T_world_board["cam"]  # the board in the robot's base, metres away
    assert 0.5 < np.linalg.norm(Z[:3, 3]) < 5 and np.all(po.T_world_board_std["cam"][1] < 2e-3)
    assert rig.bundle_adjustment["cam"].rms_px < 0.2
    # the robot's kinematic error follows its configuration, alike at neighbouring stations:
    # the block test sees it and the stds grow to cover it (issue 20), the one warning
    assert len(rig.warnings) == 1 and "correlated over time" in rig.warnings[0], rig.warnings
    assert rig.uncertainty is not None and "joint handeye" in rig.uncertainty.grown
    # the joint written the other way round: T_q_p is then T_cam_flange, the same X
    swapped = _run(tmp_path, "flange, cam", "out_swapped").joints["handeye"]
    assert swapped.T_q_p is not None
    d = swapped.T_q_p @ j.T_q_p  # X^-1 X
    assert np.linalg.norm(se3.rotvec_from_matrix(d[:3, :3])) < 1e-6
    assert np.linalg.norm(d[:3, 3]) < 1e-6
    # exported for ROS (issue 22, item 3): easy_handeye's YAML with the user's frame names,
    # the same X either way the joint is written, and the lines that publish it
    for out, rig_dir in (("he.yaml", "out"), ("he_swapped.yaml", "out_swapped")):
        res = acscal(
            "export", tmp_path / rig_dir / "rig.yaml", "--format", "handeye",
            "--camera-name", "flange=tool0", "--camera-name", "cam=camera_optical",
            "--base-frame", "base_link", "-o", tmp_path / out,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        doc = yaml.safe_load((tmp_path / out).read_text())
        p = doc["parameters"]
        assert p["eye_on_hand"] is True and p["robot_effector_frame"] == "tool0"
        assert p["tracking_base_frame"] == "camera_optical" and p["robot_base_frame"] == "base_link"
        tr = doc["transformation"]
        X = se3.transforms_from_rt(
            se3.matrix_from_quat_xyzw(np.array([[tr[k] for k in ("qx", "qy", "qz", "qw")]]))[0],
            np.array([tr["x"], tr["y"], tr["z"]]),
        )
        d = X @ se3.invert_transforms(j.T_q_p)  # j.T_q_p maps cam into flange: X itself
        assert np.linalg.norm(d[:3, 3]) < 1e-6 and se3.rotation_angle_deg(d[:3, :3]) < 1e-6
        ros1 = doc["acscal"]["static_transform_publisher"]["ros1"]
        assert ros1[0].endswith("tool0 camera_optical") and ros1[1].endswith("base_link board")
        assert ros1[0] in res.stdout
        assert np.all(np.array(doc["acscal"]["transformation_std"]["translation_m"]) < 2e-3)
