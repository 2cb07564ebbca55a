"""Target YAML files round trip, and the intrinsics artifact keeps its target."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from acs_cli.core.targets import AprilGrid, Charuco, Checkerboard, Target
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.target import read_target_yaml, target_to_mapping, write_target_yaml


@pytest.mark.parametrize(
    "target",
    [
        AprilGrid(6, 6, 0.088, 0.3),
        AprilGrid(3, 4, 0.0125, 0.25),
        Charuco(11, 8, 0.03, 0.022, "DICT_5X5_100"),
        Charuco(5, 7, 0.04, 0.031, "DICT_APRILTAG_36h11"),
        Checkerboard(9, 6, 0.025),
    ],
)
def test_target_yaml_round_trip(tmp_path: Path, target: Target) -> None:
    f = tmp_path / "target.yaml"
    write_target_yaml(f, target)
    assert read_target_yaml(f) == target
    doc = yaml.safe_load(f.read_text())
    assert doc["target_type"] == target.kind
    assert not list(tmp_path.glob("*.tmp*"))  # written atomically, nothing left behind


def test_intrinsics_artifact_keeps_the_target(tmp_path: Path) -> None:
    target = AprilGrid(6, 6, 0.088, 0.3)
    art = IntrinsicsArtifact(
        model="pinhole",
        image_size=(640, 480),
        camera_matrix=np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 1]]),
        distortion=np.zeros(5),
        target=target_to_mapping(target),
        header={"schema": "acscal/intrinsics", "schema_version": 1},
    )
    f = tmp_path / "intrinsics.yaml"
    art.save(f)
    back = IntrinsicsArtifact.load(f)
    assert back.target == target_to_mapping(target)
    assert back.board is None
