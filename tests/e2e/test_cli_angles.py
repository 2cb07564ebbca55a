"""``acscal trajectory`` writes each joint's angles per frame (issue 22, item 1): angles.csv
beside the TUM files, through the real CLI on a simulated hinge and ball pair."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.core.angles import articulation_from_orientations, hinge_angles
from acs_cli.io.angles import ANGLE_COLUMNS, read_angles_csv
from acs_cli.io.trajectory import write_tum
from sample_data_gen.rig_sim import rig_recording

SIGMA_ROT_DEG, SIGMA_TRANS = 0.1, 0.002


def _calibrated(tmp: Path, jtype: str, seed: int):  # type: ignore[no-untyped-def]
    """A pair joined by ``jtype`` (general motion), self-calibrated by ``acscal relpose``."""
    rng = np.random.default_rng(seed)
    rec = rig_recording(
        rng, 80, joints=(("j", ("a", "b"), jtype),), reference="a",
        sigma_rot_deg=SIGMA_ROT_DEG, sigma_trans=SIGMA_TRANS,
    )  # fmt: skip
    a, b = tmp / "a.tum", tmp / "b.tum"
    write_tum(a, rec.timestamps, rec.T_wc_c["a"])
    write_tum(b, rec.timestamps, rec.T_wc_c["b"])
    rel = tmp / "relpose.yaml"
    res = acscal(
        "relpose", "--self-calibrate", "--joint-type", jtype,
        "--poses-a", a, "--poses-b", b, "-o", rel,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return rec, a, b, rel


def test_a_hinge_angle_per_frame_within_its_std(tmp_path: Path) -> None:
    rec, a, b, rel = _calibrated(tmp_path, "hinge", 7)
    out = tmp_path / "traj"
    res = acscal("trajectory", "--relpose", rel, "--poses-a", a, "--poses-b", b, "-o", out)
    assert res.returncode == 0, res.stderr
    header = (out / "angles.csv").read_text().splitlines()[0].split(",")
    assert tuple(header) == ANGLE_COLUMNS and header[:4] == [
        "time", "joint", "angle_deg", "angle_std_deg",
    ]  # fmt: skip
    got = read_angles_csv(out / "angles.csv")["joint"]
    art = yaml.safe_load((out / "trajectory.yaml").read_text())
    k = art["angles"]["zero"]["index"]
    assert got["angle_deg"][k] == 0.0 and got["angle_std_deg"][k] == 0.0
    # the truth: the true orientations about the true axis (in a), zero at the same instant
    e = rec.edges["j"]
    D = articulation_from_orientations(rec.T_W_c["a"][:, :3, :3], rec.T_W_c["b"][:, :3, :3], k)
    truth = hinge_angles(D, e.axis_p, 0.0, k).angle_deg
    # the axis relpose found may point the other way: the angle then has the other sign
    sign = float(np.sign(np.dot(art["angles"]["axis_in_a"], e.axis_p)))
    err = (sign * got["angle_deg"] - truth)[np.arange(truth.size) != k]
    std = got["angle_std_deg"][np.arange(truth.size) != k]
    z = float(np.sqrt(np.mean((err / std) ** 2)))
    assert 0.3 < z < 2.5, z  # one draw: the reference's own noise shifts every angle alike
    assert np.corrcoef(sign * got["angle_deg"], truth)[0, 1] > 0.999
    assert art["angles"]["wobble_rms_deg"] < 5 * SIGMA_ROT_DEG
    assert np.allclose(got["time"], rec.timestamps)


@pytest.fixture(scope="module")
def ball(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    return _calibrated(tmp_path_factory.mktemp("ball"), "ball", 8)


def test_a_ball_joint_gets_rotation_vectors_and_the_euler_sequence_asked(
    ball,
    tmp_path: Path,  # type: ignore[no-untyped-def]
) -> None:
    rec, a, b, rel = ball
    out = tmp_path / "traj"
    res = acscal(
        "trajectory", "--relpose", rel, "--poses-a", a, "--poses-b", b, "-o", out,
        "--euler", "YXZ",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    got = read_angles_csv(out / "angles.csv")["joint"]
    assert set(got["euler_sequence"]) == {"YXZ"}
    assert np.all(np.isnan(got["angle_deg"]))  # a hinge's column stays empty
    k = yaml.safe_load((out / "trajectory.yaml").read_text())["angles"]["zero"]["index"]
    D = articulation_from_orientations(rec.T_W_c["a"][:, :3, :3], rec.T_W_c["b"][:, :3, :3], k)
    from scipy.spatial.transform import Rotation

    truth = Rotation.from_matrix(D).as_rotvec(degrees=True)
    rv = np.stack([got[f"rotvec_{c}_deg"] for c in "xyz"], axis=1)
    assert np.abs(rv - truth).max() < 6 * 2 * SIGMA_ROT_DEG * 3


@pytest.mark.parametrize("bad", ["ABC", "xyz1"])
def test_an_unknown_euler_sequence_exits_2_and_writes_nothing(
    ball,
    tmp_path: Path,
    bad: str,  # type: ignore[no-untyped-def]
) -> None:
    _, a, b, rel = ball
    out = tmp_path / "traj"
    res = acscal(
        "trajectory", "--relpose", rel, "--poses-a", a, "--poses-b", b, "-o", out, "--euler", bad
    )
    assert res.returncode == 2 and "is not an Euler sequence" in res.stderr, res.stderr
    assert not out.exists() or not any(out.iterdir())


def test_angles_zero_where_the_user_says(ball, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Issue 22, item 1: zero at the reference instant unless the user gives another zero
    (``--zero-at``: the frame nearest that time); a time outside the recording exits 2 and
    writes nothing."""
    rec, a, b, rel = ball
    out = tmp_path / "traj"
    at = float(rec.timestamps[40]) + 0.004  # nearest frame 40 (30 fps)
    res = acscal("trajectory", "--relpose", rel, "--poses-a", a, "--poses-b", b, "-o", out,
                 "--zero-at", str(at))  # fmt: skip
    assert res.returncode == 0, res.stderr
    got = read_angles_csv(out / "angles.csv")["joint"]
    zero = yaml.safe_load((out / "trajectory.yaml").read_text())["angles"]["zero"]
    assert zero["index"] == 40 and zero["timestamp_a"] == pytest.approx(rec.timestamps[40])
    rv = np.stack([got[f"rotvec_{c}_deg"] for c in "xyz"], axis=1)
    assert np.all(rv[40] == 0.0) and np.abs(rv[0]).max() > 1.0
    D = articulation_from_orientations(rec.T_W_c["a"][:, :3, :3], rec.T_W_c["b"][:, :3, :3], 40)
    from scipy.spatial.transform import Rotation

    truth = Rotation.from_matrix(D).as_rotvec(degrees=True)
    assert np.abs(rv - truth).max() < 6 * 2 * SIGMA_ROT_DEG * 3
    bad = tmp_path / "bad"
    res = acscal("trajectory", "--relpose", rel, "--poses-a", a, "--poses-b", b, "-o", bad,
                 "--zero-at", "1e6")  # fmt: skip
    assert res.returncode == 2 and "--zero-at" in res.stderr, res.stderr
    assert not bad.exists() or not any(bad.iterdir())
