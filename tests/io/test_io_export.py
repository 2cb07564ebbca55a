"""OpenCV FileStorage exports (the Kalibr camchain: tests/io/test_rig_export.py)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.io.export import write_opencv_yaml


def test_opencv_yaml_read_back(tmp_path: Path, rng: np.random.Generator) -> None:
    T = se3.transforms_from_rt(Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3))
    K = np.array([[500.0, 0, 320], [0, 505.0, 240], [0, 0, 1]])
    path = tmp_path / "out" / "calib.yaml"
    write_opencv_yaml(
        path,
        {
            "T_b_a": T,
            "K": K,
            "scale_phi_ba": 0.75,
            "n_frames": 12,
            "units": "A units",
            "idx": np.arange(3),
        },
    )
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        assert fs.isOpened()
        np.testing.assert_array_equal(fs.getNode("T_b_a").mat(), T)
        np.testing.assert_array_equal(fs.getNode("K").mat(), K)
        assert fs.getNode("scale_phi_ba").real() == 0.75
        assert int(fs.getNode("n_frames").real()) == 12
        assert fs.getNode("units").string() == "A units"
        assert fs.getNode("idx").mat().ravel().tolist() == [0, 1, 2]
    finally:
        fs.release()
    assert [p.name for p in path.parent.iterdir()] == ["calib.yaml"]


def test_opencv_yaml_other_suffix(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    write_opencv_yaml(path, {"x": 1.5})
    assert path.read_text().startswith("%YAML")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.getNode("x").real() == 1.5
    fs.release()


def test_opencv_yaml_bad_key(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="key"):
        write_opencv_yaml(tmp_path / "a.yaml", {"a b": 1.0})
    assert list(tmp_path.iterdir()) == []
