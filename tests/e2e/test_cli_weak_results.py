"""One policy for poorly determined results (issue 13, item 1), end to end: a verdict in
every joint and relpose artifact; warnings past the warning level; exit 3 past the refusal
level unless ``--accept-weak``, whose result is marked weak in the artifact and the export."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.trajectory import write_tum
from sample_data_gen import acs_sim


def load(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A rig's fixed-joint and general recordings, and another rig's fixed-joint one."""
    rng = np.random.default_rng(77)
    d = tmp_path_factory.mktemp("weak")
    out: dict[str, Path] = {}
    rig, other = acs_sim.make_rig(rng), acs_sim.make_rig(rng)
    for name, seq in (
        ("fixed", acs_sim.fixed_joint_sequence(rng, rig, 30)),
        ("general", acs_sim.general_sequence(rng, rig, 30)),
        ("other", acs_sim.fixed_joint_sequence(rng, other, 30)),
    ):
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            out[f"{name}_{cam}"] = p = d / f"{name}_{cam}.tum"
            write_tum(p, seq.timestamps, acs_sim.add_pose_noise(rng, T, 0.2, 0.003))
    return out


def _joint(files: dict[str, Path], name: str, out: Path) -> Path:
    res = acscal(
        "joint", "--fixed-joint", "--poses-a", files[f"{name}_a"], "--poses-b",
        files[f"{name}_b"], "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out


def test_a_good_calibration_says_good(files: dict[str, Path], tmp_path: Path) -> None:
    doc = load(_joint(files, "fixed", tmp_path / "joint.yaml"))
    assert doc["verdict"]["level"] == "good" and doc["warnings"] == []
    measures = doc["verdict"]["measures"]
    assert {"joint_std_fraction (the joint in A)", "residual_fraction (the joint in B)"} <= set(
        measures
    )
    assert all(m["level"] == "good" for m in measures.values())
    # independent pose noise: the block test for correlated errors ran and grew nothing
    for key in ("a", "b"):
        u = doc["quality"]["uncertainty"][key]
        assert u["blocks"] > 0 and u["grown"] == [] and u["std_factor"] == 1.0


def test_a_joint_from_another_rig_is_refused_then_accepted_and_marked(
    files: dict[str, Path], tmp_path: Path
) -> None:
    joint = _joint(files, "other", tmp_path / "other_joint.yaml")
    rel = tmp_path / "relpose.yaml"
    args = ("relpose", "--joint", joint, "--poses-a", files["general_a"], "--poses-b",
            files["general_b"], "-o", rel)  # fmt: skip
    res = acscal(*args)
    assert res.returncode == 3, res.stderr
    assert "--accept-weak" in res.stderr and "refusal level" in res.stderr
    assert "the joint file does not fit this recording" in res.stderr  # the cause, named
    assert not rel.exists()

    res = acscal(*args, "--accept-weak")
    assert res.returncode == 0, res.stderr
    doc = load(rel)
    assert doc["verdict"]["level"] == "refused" and doc["verdict"]["accepted_weak"] is True
    assert any("--accept-weak" in w for w in doc["warnings"])
    assert "warning:" in res.stderr

    exported = tmp_path / "relpose_cv.yaml"
    res = acscal("export", rel, "--format", "opencv", "-o", exported)
    assert res.returncode == 0, res.stderr
    text = exported.read_text()
    assert "WEAK RESULT" in text and "refused (--accept-weak)" in text

    # ... and in the trajectories drawn from it
    res = acscal(
        "trajectory", "--relpose", rel, "--poses-a", files["general_a"], "--poses-b",
        files["general_b"], "-o", tmp_path / "traj",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "WEAK RESULT: relpose.yaml" in (tmp_path / "traj" / "cam_a.tum").read_text()
    assert "warning: WEAK RESULT" in res.stderr


def test_quaternions_in_w_first_order_are_refused(files: dict[str, Path], tmp_path: Path) -> None:
    """A TUM file written with qw first: the joint does not fit the poses at all, and the
    diagnosis names the cause."""
    lines = files["fixed_a"].read_text().split("\n")
    swapped = tmp_path / "wxyz.tum"
    rows = []
    for line in lines:
        v = line.split()
        if len(v) == 8 and not line.startswith("#"):
            v = [*v[:4], v[7], *v[4:7]]  # t x y z qw qx qy qz, read as qx qy qz qw
        rows.append(" ".join(v))
    swapped.write_text("\n".join(rows))
    res = acscal("joint", "--fixed-joint", "--poses-a", swapped, "-o", tmp_path / "j.yaml")
    assert res.returncode == 3, res.stderr
    assert "residual" in res.stderr and "--accept-weak" in res.stderr
    assert "camera A's quaternions look written in w-x-y-z order" in res.stderr


def test_a_std_past_the_warning_level_warns(tmp_path: Path) -> None:
    """A narrow fixed-joint motion (about 3 deg) at 0.6 deg / 6 mm of pose noise: the joint's
    std is about 7% of its distance, past the warning level (5%), not the refusal level
    (10%): written, with a warning in the file and on stderr."""
    rng = np.random.default_rng(5)
    n = 30
    R = se3.matrix_from_rotvec(np.radians(3.0) * rng.normal(size=(n, 3)) * [1, 1, 0.5])
    o = np.array([0.0, 0.0, 0.4])
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = np.array([0.1, 0.2, 1.0]) - R @ o
    path = tmp_path / "narrow.tum"
    write_tum(path, np.arange(n, dtype=float), acs_sim.add_pose_noise(rng, T, 0.6, 0.006))
    res = acscal("joint", "--fixed-joint", "--poses-a", path, "-o", tmp_path / "j.yaml")
    assert res.returncode == 0, res.stderr
    doc = load(tmp_path / "j.yaml")
    assert doc["verdict"]["level"] == "weak" and doc["verdict"]["accepted_weak"] is False
    m = doc["verdict"]["measures"]["joint_std_fraction (the joint in A)"]
    assert m["level"] == "weak" and m["warn"] < m["value"] < m["refuse"]
    assert any("joint's largest standard deviation" in w for w in doc["warnings"])
    assert "warning: the joint in A: the joint's largest standard deviation" in res.stderr


def test_the_paper_method_thrown_by_outliers_is_named_not_the_joint_file(
    files: dict[str, Path], tmp_path: Path
) -> None:
    """Issue 13: the paper's linear method on poses with gross outliers. Its residual is
    huge; the cause is the method (the refined one fits the same poses), not the joint file,
    which is this rig's."""
    joint = _joint(files, "fixed", tmp_path / "joint.yaml")
    rng = np.random.default_rng(3)
    for cam in ("a", "b"):
        text = [ln.split() for ln in files[f"general_{cam}"].read_text().splitlines()]
        rows = [r for r in text if len(r) == 8 and not r[0].startswith("#")]
        t = np.array([float(r[0]) for r in rows])
        q = np.array([[float(x) for x in r[4:8]] for r in rows])
        T = np.tile(np.eye(4), (len(rows), 1, 1))
        T[:, :3, :3] = se3.matrix_from_quat_xyzw(q)
        T[:, :3, 3] = [[float(x) for x in r[1:4]] for r in rows]
        if cam == "b":  # 6 gross outliers in B (20%)
            T = acs_sim.corrupt_poses(
                rng, T, np.array([0.0, 0.0, 0.3]), np.array([3, 7, 11, 15, 19, 23])
            )
        write_tum(tmp_path / f"{cam}.tum", t, T)
    res = acscal(
        "relpose", "--method", "paper", "--joint", joint, "--poses-a", tmp_path / "a.tum",
        "--poses-b", tmp_path / "b.tum", "-o", tmp_path / "r.yaml",
    )  # fmt: skip
    assert res.returncode == 3, res.stderr
    assert "the paper's linear method is thrown by poses that do not fit" in res.stderr
    assert "--method refined" in res.stderr and "another rig" not in res.stderr
    res = acscal(
        "relpose", "--joint", joint, "--poses-a", tmp_path / "a.tum", "--poses-b",
        tmp_path / "b.tum", "-o", tmp_path / "r.yaml",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
