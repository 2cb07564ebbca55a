"""Each poses file is read once per command (issue 19): ``acscal joint --overlap``,
``acscal relpose`` and ``acscal run`` on a rig, run in-process with every open of a poses
file for reading counted."""

from __future__ import annotations

import builtins
import io
from collections import Counter
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from acs_cli.cli.main import main
from acs_cli.core import se3
from acs_cli.io.artifacts import make_header
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.joint import JointArtifact
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.rig import RigArtifact
from acs_cli.io.trajectory import Trajectory, write_tum
from sample_data_gen import acs_sim

K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def overlap(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Poses NPZs of two cameras seeing one 9x6 checkerboard (the world), with their corners
    and intrinsics files, as ``acscal poses`` writes them."""
    root = tmp_path_factory.mktemp("overlap")
    rng = np.random.default_rng(5)
    gx, gy = np.meshgrid(np.arange(9), np.arange(6))
    board = np.stack([gx.ravel() * 0.1, gy.ravel() * 0.1, np.zeros(gx.size)], axis=1)
    # A 1.5 m in front of the board, B beside it on a ball joint: both see the board
    rig = acs_sim.SyntheticRig(np.array([0.15, 0.0, 0.1]), np.array([-0.15, 0.0, 0.1]), np.eye(3))
    n = 40
    t = np.array([0.4, 0.25, -1.5]) + rng.uniform(-0.2, 0.2, size=(n, 3))
    T_w_a = se3.transforms_from_rt(acs_sim.random_rotations(rng, n, 15.0), t)
    T_w = {"a": T_w_a, "b": T_w_a @ rig.T_a_b(rig.articulations(rng, n, 20.0))}
    files = {}
    for cam, T in T_w.items():
        intr = root / f"intrinsics_{cam}.yaml"
        IntrinsicsArtifact(
            model="pinhole", image_size=(640, 480), camera_matrix=K, distortion=np.zeros(5),
            header=make_header("intrinsics", {}, "test", {}, {}),
        ).save(intr)  # fmt: skip
        T_c_w = se3.invert_transforms(T)
        px = np.stack(
            [cv2.projectPoints(board, cv2.Rodrigues(G[:3, :3])[0], G[:3, 3], K, None)[0][:, 0]
             for G in T_c_w]
        ) + rng.normal(scale=0.2, size=(n, board.shape[0], 2))  # fmt: skip
        noisy = acs_sim.add_pose_noise(rng, T, 0.1, 0.002)
        files[cam] = root / f"poses_{cam}.npz"
        PosesArtifact(
            trajectory=Trajectory(np.arange(n) / 10.0, noisy, "x", "npz", True),
            corners=px,
            board_points=board,
            header=make_header("poses", {}, "test", {}, {}) | {"intrinsics_file": str(intr)},
        ).save(files[cam])
        files[f"{cam}_tum"] = root / f"poses_{cam}.tum"  # a text format: told by its content
        write_tum(files[f"{cam}_tum"], np.arange(n) / 10.0, noisy)
    (root / "rig.yaml").write_text(
        f"schema_version: 2\noutput: {root / 'out'}\nworld: shared\ncameras:\n"
        f"  a: {{poses: {files['a']}}}\n  b: {{poses: {files['b']}}}\n"
        "joints:\n  j: {between: [a, b], type: ball}\n",
        encoding="utf-8",
    )
    return files


def _reads(monkeypatch: pytest.MonkeyPatch, paths: list[Path], argv: list[str]) -> dict[str, int]:
    """Run ``acscal ARGV`` in-process; how many times each of ``paths`` was opened to read."""
    watched = {p.resolve(): p.name for p in paths}
    count: Counter[str] = Counter()
    real_open = builtins.open

    def counting_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        if isinstance(file, (str, Path)) and not set(mode) & set("wax+"):
            name = watched.get(Path(file).resolve())
            if name is not None:
                count[name] += 1
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", counting_open)
    monkeypatch.setattr(io, "open", counting_open)
    try:
        main(argv)
    finally:
        monkeypatch.undo()
    return {p.name: count[p.name] for p in paths}


def test_joint_overlap_reads_each_poses_file_once(
    overlap: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    got = _reads(
        monkeypatch,
        [overlap["a"], overlap["b"]],
        ["joint", "--overlap", "--poses-a", str(overlap["a"]), "--poses-b", str(overlap["b"]),
         "-o", str(tmp_path / "joint.yaml")],
    )  # fmt: skip
    assert got == {"poses_a.npz": 1, "poses_b.npz": 1}
    # the corners were used (the board's two orders tried, the bundle adjusted)
    assert set(JointArtifact.load(tmp_path / "joint.yaml").quality.bundle_adjustment) == {"a", "b"}


@pytest.mark.parametrize("suffix", ["", "_tum"])
def test_relpose_reads_each_poses_file_once(
    overlap: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    a, b = overlap["a" + suffix], overlap["b" + suffix]
    got = _reads(
        monkeypatch,
        [a, b],
        ["relpose", "--self-calibrate", "--poses-a", str(a), "--poses-b", str(b),
         "-o", str(tmp_path / "relpose.yaml")],
    )  # fmt: skip
    assert got == {a.name: 1, b.name: 1}
    bundled = RelposeArtifact.load(tmp_path / "relpose.yaml").quality.bundle_adjustment
    assert set(bundled) == ({"a", "b"} if suffix == "" else set())


def test_run_on_a_rig_reads_each_poses_file_once(
    overlap: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    config = overlap["a"].parent / "rig.yaml"
    got = _reads(monkeypatch, [overlap["a"], overlap["b"]], ["run", str(config)])
    assert got == {"poses_a.npz": 1, "poses_b.npz": 1}
    rig = RigArtifact.load(config.parent / "out" / "rig.yaml")
    assert set(rig.bundle_adjustment) == {"a", "b"}
