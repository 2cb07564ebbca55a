"""angles.csv written then read (acs_cli.io.angles)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.core.angles import BallAngles, HingeAngles
from acs_cli.errors import InputError
from acs_cli.io.angles import ANGLE_COLUMNS, JointAngleSeries, read_angles_csv, write_angles_csv


def test_hinge_and_ball_rows_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    n = 6
    t = np.cumsum(rng.uniform(0.01, 0.1, n)) + 1.7e9  # epoch seconds keep their digits
    h = HingeAngles(rng.normal(size=n), np.full(n, 0.2), np.abs(rng.normal(size=n)))
    e_std = np.abs(rng.normal(size=(n, 3)))
    e_std[2, 1] = np.nan  # gimbal lock: an empty cell
    b = BallAngles(
        rng.normal(size=(n, 3)), np.full((n, 3), 0.3), "zxy", rng.normal(size=(n, 3)), e_std
    )
    path = tmp_path / "angles.csv"
    write_angles_csv(path, [JointAngleSeries("knee", t, h), JointAngleSeries("hip", t, b)])
    assert path.read_text().splitlines()[0] == ",".join(ANGLE_COLUMNS)
    got = read_angles_csv(path)
    assert np.array_equal(got["knee"]["time"], t)
    assert np.allclose(got["knee"]["angle_deg"], h.angle_deg, atol=1e-6)
    assert np.all(np.isnan(got["knee"]["rotvec_x_deg"]))
    assert np.allclose(got["hip"]["euler_3_deg"], b.euler_deg[:, 2], atol=1e-6)
    assert np.isnan(got["hip"]["euler_2_std_deg"][2]) and set(got["hip"]["euler_sequence"]) == {
        "zxy"
    }


def test_another_csv_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "x.csv"
    p.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match=r"not an angles\.csv"):
        read_angles_csv(p)
