"""angles.csv written then read (acs_cli.io.angles)."""

from __future__ import annotations

import csv
import io
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


def _rows_one_by_one(series: list[JointAngleSeries]) -> str:
    """angles.csv as the former writer made it: a row at a time, a cell at a time."""

    def num(x: float) -> str:
        return "" if not np.isfinite(x) else f"{float(x):.6f}"

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(ANGLE_COLUMNS)
    for s in series:
        a = s.angles
        for i, t in enumerate(np.asarray(s.times, dtype=float)):
            row = dict.fromkeys(ANGLE_COLUMNS, "")
            row["time"], row["joint"] = repr(float(t)), s.joint
            if isinstance(a, HingeAngles):
                row["angle_deg"] = num(a.angle_deg[i])
                row["angle_std_deg"] = num(a.angle_std_deg[i])
                row["wobble_deg"] = num(a.wobble_deg[i])
            else:
                for k, c in enumerate("xyz"):
                    row[f"rotvec_{c}_deg"] = num(a.rotvec_deg[i, k])
                row["rotvec_std_deg"] = num(a.rotvec_std_deg[i, 0])
                row["euler_sequence"] = a.sequence
                for k in range(3):
                    row[f"euler_{k + 1}_deg"] = num(a.euler_deg[i, k])
                    row[f"euler_{k + 1}_std_deg"] = num(a.euler_std_deg[i, k])
            w.writerow([row[c] for c in ANGLE_COLUMNS])
    return buf.getvalue()


def test_columns_written_as_rows_one_by_one(tmp_path: Path, rng: np.random.Generator) -> None:
    """The writer formats a column at a time: the same text as a row and a cell at a time,
    empty cells where a value is not finite, a joint's name quoted as csv quotes it."""
    n = 5
    t = np.cumsum(rng.uniform(0.01, 0.1, n)) + 1.7e9
    angle = rng.normal(size=n) * 1e3
    angle[1] = -0.0
    angle[3] = np.inf
    h = HingeAngles(angle, np.where(np.arange(n) == 0, 0.0, 0.2), np.abs(rng.normal(size=n)))
    m = 3  # the ball joint's frames
    rv_std = np.full((m, 3), np.nan)
    rv_std[1] = 0.0  # as rig_angles: no std but 0 at the zero instant
    e = rng.normal(size=(m, 3)) * 100
    e[2, 0] = -1e-9  # rounds to -0.000000
    b = BallAngles(rng.normal(size=(m, 3)), rv_std, "ZXY", e, np.full((m, 3), np.nan))
    series = [JointAngleSeries("knee, left", t, h), JointAngleSeries("hip", t[:m], b)]
    path = tmp_path / "angles.csv"
    write_angles_csv(path, series)
    assert path.read_text() == _rows_one_by_one(series)
    assert '"knee, left"' in path.read_text()


def test_another_csv_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "x.csv"
    p.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match=r"not an angles\.csv"):
        read_angles_csv(p)
