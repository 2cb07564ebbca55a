"""A rig whose body's poses are in another convention (issue 19/20: a robot's poses read the
wrong way round): the run names the body, the reading that fits and the key, exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.trajectory import write_tum
from sample_data_gen import acs_sim


def test_a_robots_poses_given_inverted_are_named(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    cam, flange, _ = acs_sim.hand_eye_pair(rng, 30, 0.1, 0.001)
    t = np.arange(30) / 10.0
    write_tum(tmp_path / "cam.tum", t, cam)
    write_tum(tmp_path / "flange.tum", t, se3.invert_transforms(flange))  # the wrong way round
    (tmp_path / "c.yaml").write_text(
        "schema_version: 2\noutput: out/\ncameras:\n  cam: {poses: cam.tum}\n"
        "  flange: {poses: flange.tum}\njoints:\n  he: {between: [cam, flange], type: rigid}\n"
    )
    res = acscal("run", tmp_path / "c.yaml")
    assert res.returncode == 2, res.stderr
    assert "cameras.flange.poses: body flange's poses fit the rig inverted" in res.stderr
    assert "T_flange_world given where T_world_flange is expected" in res.stderr
    assert not (tmp_path / "out" / "rig.yaml").exists()
    # the fix the message names: the entry's invert key
    text = (tmp_path / "c.yaml").read_text()
    (tmp_path / "c.yaml").write_text(
        text.replace("{poses: flange.tum}", "{poses: flange.tum, invert: true}")
    )
    res = acscal("run", tmp_path / "c.yaml")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "out" / "rig.yaml").is_file()
