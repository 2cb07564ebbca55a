"""Trajectory readers and writers: TUM, KITTI, COLMAP, NPZ and format dispatch."""

from __future__ import annotations

import io
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples
from scipy.spatial.transform import Rotation

import acs_cli.io.trajectory as trajectory_io
from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import (
    Trajectory,
    read_trajectory,
    write_kitti,
    write_npz_poses,
    write_tum,
)


def random_poses(rng: np.random.Generator, n: int, scale: float = 5.0) -> np.ndarray:
    """``(n, 4, 4)`` random rigid transforms."""
    R = Rotation.random(n, random_state=rng).as_matrix()
    t = rng.uniform(-scale, scale, size=(n, 3))
    return se3.transforms_from_rt(R, t).reshape(n, 4, 4)


def assert_line(info: pytest.ExceptionInfo[InputError], path: Path, line: int) -> None:
    err = info.value
    assert err.path == str(path)
    assert err.line == line
    assert str(err).startswith(f"{path}:{line}: ")
    assert "\n" not in str(err)


TUM_GOOD = """# timestamp tx ty tz qx qy qz qw
1.0 0 0 0 0 0 0 1

2.0 1 0 0 0 0 0 1
# a comment
3.0 2 0 0 0 0 0.7071067811865476 0.7071067811865476
"""


# ----------------------------------------------------------------------------- TUM


def test_tum_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 20)
    t = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.1, 20))
    path = tmp_path / "a.tum"
    write_tum(path, t, T)
    traj = read_trajectory(path, "tum")
    assert traj.format == "tum" and traj.has_timestamps and traj.names == ()
    assert traj.source == str(path)
    np.testing.assert_allclose(traj.timestamps, t, atol=1e-9, rtol=0)
    np.testing.assert_allclose(traj.T_world_cam, T, atol=1e-12, rtol=0)
    # quaternions written with w >= 0
    q = np.loadtxt(path)[:, 4:]
    assert np.all(q[:, 3] >= 0)


def test_tum_comments_blank_lines(tmp_path: Path) -> None:
    path = tmp_path / "a.txt"
    path.write_text(TUM_GOOD)
    traj = read_trajectory(path, "tum")
    assert len(traj) == 3
    np.testing.assert_allclose(traj.timestamps, [1, 2, 3])
    np.testing.assert_allclose(traj.T_world_cam[2, :3, 3], [2, 0, 0])
    np.testing.assert_allclose(
        traj.T_world_cam[2, :3, :3], se3.matrix_from_rpy_deg([0, 0, 90]), atol=1e-12
    )


def test_tum_crlf_and_bom(tmp_path: Path) -> None:
    path = tmp_path / "a.txt"
    path.write_bytes(b"\xef\xbb\xbf" + TUM_GOOD.replace("\n", "\r\n").encode())
    assert len(read_trajectory(path, "tum")) == 3


@pytest.mark.parametrize(
    ("content", "line", "pattern"),
    [
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", 2, "expected 8 numbers"),
        ("1 0 0 0 0 0 0 1\n# c\n2 0 0 0 0 0 0 1 9\n", 3, "got 9"),
        ("1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n", 2, "not a number: 'x'"),
        ("1 0 0 0 0 0 0 1\n\n2 0 nan 0 0 0 0 1\n", 3, "NaN or inf"),
        ("1 0 0 0 0 0 0 1\n2 0 0 inf 0 0 0 1\n", 2, "NaN or inf"),
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1.01\n", 2, "norm"),
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 0\n", 2, "norm"),
        ("1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", 2, "repeats"),
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n\n1.5 0 0 0 0 0 0 1\n", 4, "before"),
        ("1 0 0 0 0 0 0 1\n\xff\n", 2, "UTF-8"),
    ],
)
def test_tum_malformed(tmp_path: Path, content: str, line: int, pattern: str) -> None:
    path = tmp_path / "bad.txt"
    path.write_bytes(content.encode("latin-1"))
    with pytest.raises(InputError, match=pattern) as info:
        read_trajectory(path, "tum")
    assert_line(info, path, line)


def test_tum_quaternion_within_tolerance_is_normalised(tmp_path: Path) -> None:
    path = tmp_path / "a.txt"
    path.write_text("1 0 0 0 0 0 0 1.0005\n")
    traj = read_trajectory(path, "tum")
    np.testing.assert_allclose(traj.T_world_cam[0], np.eye(4), atol=1e-15)


@pytest.mark.parametrize("content", ["", "# only a comment\n\n", "   \n"])
def test_tum_empty(tmp_path: Path, content: str) -> None:
    path = tmp_path / "empty.txt"
    path.write_text(content)
    with pytest.raises(InputError, match="no poses") as info:
        read_trajectory(path, "tum")
    assert info.value.path == str(path)


def test_missing_file(tmp_path: Path) -> None:
    for fmt in ("tum", "kitti", "colmap", "npz", "auto"):
        with pytest.raises(InputError, match="no such file"):
            read_trajectory(tmp_path / "nope.txt", fmt)


def test_write_tum_rejects_bad_input(tmp_path: Path) -> None:
    with pytest.raises(InputError):
        write_tum(tmp_path / "x.txt", [0.0, 1.0], np.eye(4)[None])
    bad = np.eye(4)[None].copy()
    bad[0, 0, 0] = 2.0
    with pytest.raises(InputError):
        write_tum(tmp_path / "x.txt", [0.0], bad)
    assert not (tmp_path / "x.txt").exists()


def _tum_rows(t: np.ndarray, T: np.ndarray, stamps: list[str] | None = None) -> str:
    """The TUM rows as numpy's savetxt formats them (write_tum's former writer), a row at a
    time: ``%.9f`` (or the given stamps), then ``%.15g`` x 7."""
    q = se3.quat_xyzw_from_matrix(T[:, :3, :3])
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([T[:, :3, 3], q]), fmt=["%.15g"] * 7)
    rows = buf.getvalue().splitlines(keepends=True)
    stamps = [f"{v:.9f}" for v in t] if stamps is None else stamps
    return "".join(f"{a} {b}" for a, b in zip(stamps, rows, strict=True))


def test_write_tum_rows_are_savetxt_rows(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rows formatted a block at a time are numpy's savetxt rows, digit for digit, across
    the blocks' seams, with times from seconds or from nanoseconds, under a note."""
    monkeypatch.setattr(trajectory_io, "_TUM_BLOCK", 3)
    n = 8
    T = random_poses(rng, n)
    T[0, :3, :3] = np.eye(3)  # qx = -0.0 or 0
    T[1, :3, 3] = [-0.0, 1e-300, 123456789012345.7]  # signed zero, exponents, 15 digits
    T[2, :3, 3] = [1e16, -2.5e-5, 1.0 / 3.0]
    t = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.1, n))
    path = tmp_path / "a.tum"
    write_tum(path, t, T)
    assert path.read_text() == "# timestamp tx ty tz qx qy qz qw\n" + _tum_rows(t, T)
    ns = np.array([-1_500_000_000, 0, 7, 10**9, 1_700_000_000_123_456_789, *range(11, 14)])
    stamps = ["-1.500000000", "0.000000000", "0.000000007", "1.000000000"]
    stamps += ["1700000000.123456789", "0.000000011", "0.000000012", "0.000000013"]
    write_tum(path, ns / 1e9, T, timestamps_ns=ns, note="times are frame numbers")
    expected = "# timestamp tx ty tz qx qy qz qw\n# times are frame numbers\n"
    assert path.read_text() == expected + _tum_rows(t, T, stamps)


@pytest.mark.parametrize(
    ("stamp", "expected"),
    [
        ("1_0", 10.0),  # float reads it, numpy's text reader does not: read as float reads it
        ("\u0661\u0662", 12.0),  # Arabic-Indic digits, as float reads them
    ],
)
def test_tum_tokens_only_float_reads(tmp_path: Path, stamp: str, expected: float) -> None:
    path = tmp_path / "a.tum"
    path.write_text(f"{stamp} 1 2 3 0 0 0 1\n99 1 2 3 0 0 0 1\n", encoding="utf-8")
    traj = read_trajectory(path)
    assert traj.timestamps[0] == expected and traj.timestamps[1] == 99.0
    assert traj.T_world_cam[1, 0, 3] == 1.0


def test_tum_carriage_return_inside_a_line(tmp_path: Path) -> None:
    """A bare \\r splits numpy's text reader's rows but not str.split's tokens: one pose."""
    path = tmp_path / "a.tum"
    path.write_bytes(b"1 0 0\r0 0 0 0 1\n")
    assert len(read_trajectory(path, "tum")) == 1


def _nanoseconds_one_by_one(tokens: list[str]) -> np.ndarray | None:
    """The nanoseconds of plain decimal seconds, a token at a time (the former reader)."""
    if not all(re.match(r"^\d+(?:\.\d{0,9})?$", tok) for tok in tokens):
        return None
    out = []
    for tok in tokens:
        whole, _, frac = tok.partition(".")
        out.append(int(whole) * 10**9 + int((frac + "000000000")[:9]))
    return None if max(out) >= 2**63 else np.array(out, dtype=np.int64)


@pytest.mark.parametrize(
    "tokens",
    [
        ["0.000000000", "0.033333333", "1700000000.123456789"],  # as write_tum writes them
        ["1", "1.5", "2.", "3.123456789", "12.25"],  # 0 to 9 decimals
        ["1.0", "1.5e9"],  # not plain
        ["1.1234567891"],  # 10 decimals
        ["9223372036.854775807", "9223372036.854775808"],  # past int64
        ["9300000000.000000000"],
    ],
)
def test_exact_nanoseconds(tokens: list[str]) -> None:
    got = trajectory_io._exact_nanoseconds(tokens)
    want = _nanoseconds_one_by_one(tokens)
    assert (got is None) == (want is None)
    if want is not None:
        assert got is not None and got.dtype == np.int64 and np.array_equal(got, want)


@settings(max_examples=examples(50), suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(1, 8),
    seed=st.integers(0, 2**32 - 1),
    t0=st.floats(-1e6, 2e9),
    scale=st.floats(1e-3, 1e3),
)
def test_tum_round_trip_property(n: int, seed: int, t0: float, scale: float) -> None:
    gen = np.random.default_rng(seed)
    T = random_poses(gen, n, scale=scale)
    t = t0 + np.cumsum(gen.uniform(1e-3, 10.0, n))
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "p.tum"
        write_tum(path, t, T)
        traj = read_trajectory(path, "tum")
    np.testing.assert_allclose(traj.timestamps, t, atol=1e-9, rtol=0)
    np.testing.assert_allclose(traj.T_world_cam[:, :3, :3], T[:, :3, :3], atol=1e-9, rtol=0)
    np.testing.assert_allclose(traj.T_world_cam[:, :3, 3], T[:, :3, 3], atol=1e-9, rtol=0)


# ----------------------------------------------------------------------------- KITTI


def test_kitti_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 15)
    path = tmp_path / "k.txt"
    write_kitti(path, T)
    traj = read_trajectory(path, "kitti")
    assert traj.format == "kitti" and not traj.has_timestamps
    np.testing.assert_array_equal(traj.timestamps, np.arange(15.0))
    np.testing.assert_allclose(traj.T_world_cam, T, atol=1e-12, rtol=0)


def test_kitti_low_precision_is_reorthonormalised(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 5)
    path = tmp_path / "k.txt"
    np.savetxt(path, T[:, :3, :].reshape(5, 12), fmt="%.6e")
    traj = read_trajectory(path, "kitti")
    R = traj.T_world_cam[:, :3, :3]
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    np.testing.assert_allclose(traj.T_world_cam, T, atol=1e-5)


def _kitti_line(T: np.ndarray) -> str:
    return " ".join(f"{v:.12g}" for v in T[:3, :].ravel())


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (lambda s: s + " 1", "expected 12 numbers"),
        (lambda s: s.rsplit(" ", 1)[0], "got 11"),
        (lambda s: "a" + s, "not a number"),
        (lambda s: "nan " + s.split(" ", 1)[1], "NaN or inf"),
        (lambda s: "1.001 " + s.split(" ", 1)[1], "not orthonormal"),
    ],
)
def test_kitti_malformed(tmp_path: Path, mutate: object, pattern: str) -> None:
    lines = [_kitti_line(np.eye(4)) for _ in range(4)]
    lines[2] = mutate(lines[2])  # type: ignore[operator]
    path = tmp_path / "k.txt"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=pattern) as info:
        read_trajectory(path, "kitti")
    assert_line(info, path, 3)


def test_kitti_reflection(tmp_path: Path) -> None:
    T = np.diag([1.0, 1.0, -1.0, 1.0])
    path = tmp_path / "k.txt"
    path.write_text(_kitti_line(np.eye(4)) + "\n" + _kitti_line(T) + "\n")
    with pytest.raises(InputError, match="reflection") as info:
        read_trajectory(path, "kitti")
    assert_line(info, path, 2)


# ----------------------------------------------------------------------------- COLMAP


def write_images_txt(
    path: Path, names: list[str], T_world_cam: np.ndarray, points: bool = True
) -> None:
    """A COLMAP images.txt holding cam_from_world = inv(T_world_cam)."""
    T_cw = se3.invert_transforms(T_world_cam)
    q = Rotation.from_matrix(T_cw[:, :3, :3]).as_quat()  # x y z w
    out = [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
        f"# Number of images: {len(names)}, mean observations per image: 1",
    ]
    for k, name in enumerate(names):
        qx, qy, qz, qw = (float(v) for v in q[k])
        tx, ty, tz = (float(v) for v in T_cw[k, :3, 3])
        out.append(f"{k + 7} {qw!r} {qx!r} {qy!r} {qz!r} {tx!r} {ty!r} {tz!r} 1 {name}")
        out.append("12.5 30.25 -1 40.0 50.0 17" if points and k % 2 else "")
    path.write_text("\n".join(out) + "\n")


def test_colmap_round_trip_sorted_with_timestamps(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 6)
    stamps = [2, 10, 1, 33, 5, 7]
    names = [f"frame_{s}.png" for s in stamps]
    write_images_txt(tmp_path / "images.txt", names, T)
    for arg in (tmp_path, tmp_path / "images.txt"):
        traj = read_trajectory(arg, "colmap")
        order = np.argsort(stamps)
        assert traj.names == tuple(names[k] for k in order)
        assert traj.has_timestamps
        np.testing.assert_array_equal(traj.timestamps, np.sort(stamps))
        np.testing.assert_allclose(traj.T_world_cam, T[order], atol=1e-12)
        assert traj.format == "colmap"
        assert traj.source == str(tmp_path / "images.txt")


def test_colmap_decimal_timestamps_and_subfolders(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 3)
    names = ["left/1520000000.250.png", "left/1520000000.125.png", "left/1520000001.000.png"]
    write_images_txt(tmp_path / "images.txt", names, T)
    traj = read_trajectory(tmp_path, "colmap")
    np.testing.assert_allclose(traj.timestamps, [1520000000.125, 1520000000.25, 1520000001.0])


def test_colmap_names_without_numbers_use_index(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 3)
    names = ["c.png", "a.png", "b.png"]
    write_images_txt(tmp_path / "images.txt", names, T, points=False)
    traj = read_trajectory(tmp_path / "images.txt", "colmap")
    assert traj.names == ("a.png", "b.png", "c.png")
    assert not traj.has_timestamps
    np.testing.assert_array_equal(traj.timestamps, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(traj.T_world_cam, T[[1, 2, 0]], atol=1e-12)


def test_colmap_last_points_line_missing(tmp_path: Path) -> None:
    path = tmp_path / "images.txt"
    path.write_text("# c\n1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 1 2 3 1 b.png")
    traj = read_trajectory(path, "colmap")
    np.testing.assert_allclose(traj.T_world_cam[1, :3, 3], [-1, -2, -3])


@pytest.mark.parametrize(
    ("content", "line", "pattern"),
    [
        ("# c\n1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0\n\n", 4, "image line"),
        ("# c\n1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 x 0 0 1 b.png\n\n", 4, "image line"),
        ("# c\n1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 0 1.5 b.png\n\n", 4, "image line"),
        ("1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 nan 0 0 1 b.png\n\n", 3, "NaN or inf"),
        ("1 1 0 0 0 0 0 0 1 a.png\n1 2\n", 2, "POINTS2D"),
        ("1 1 0 0 0 0 0 0 1 a.png\n2 1 0 0 0 0 0 0 1 b.png\n", 2, "POINTS2D"),
        ("1 1 0 0 0 0 0 0 1 a.png\n\n2 0.5 0 0 0 0 0 0 1 b.png\n\n", 3, "norm"),
        ("1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 0 1 a.png\n\n", 3, "repeats"),
    ],
)
def test_colmap_malformed(tmp_path: Path, content: str, line: int, pattern: str) -> None:
    path = tmp_path / "images.txt"
    path.write_text(content)
    with pytest.raises(InputError, match=pattern) as info:
        read_trajectory(path, "colmap")
    assert_line(info, path, line)


def test_colmap_empty_and_missing(tmp_path: Path) -> None:
    (tmp_path / "images.txt").write_text("# nothing\n")
    with pytest.raises(InputError, match="no images"):
        read_trajectory(tmp_path, "colmap")
    empty = tmp_path / "sub"
    empty.mkdir()
    (empty / "images.bin").write_bytes(b"\0")
    with pytest.raises(InputError, match="model_converter"):
        read_trajectory(empty, "colmap")


# ----------------------------------------------------------------------------- NPZ


def test_npz_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 7)
    t = np.cumsum(rng.uniform(0.01, 0.1, 7))
    names = tuple(f"img_{k:03d}.png" for k in range(7))
    traj = Trajectory(t, T, source="x", format="tum", has_timestamps=True, names=names)
    rms = rng.uniform(0.1, 0.5, 7)
    path = tmp_path / "poses.npz"
    header = {"schema": "acscal/poses", "inputs": {"images": {"path": "imgs", "sha256": "00"}}}
    write_npz_poses(path, traj, {"reprojection_rms": rms}, header=header)
    back = read_trajectory(path, "npz")
    assert back.format == "npz" and back.has_timestamps and back.names == names
    np.testing.assert_allclose(back.T_world_cam, T, atol=1e-14)
    np.testing.assert_array_equal(back.timestamps, t)
    assert PosesArtifact.load(path).header == header
    with np.load(path) as z:
        assert str(z["schema"]) == "acscal/poses"
        assert int(z["schema_version"]) == 1
        np.testing.assert_array_equal(z["reprojection_rms"], rms)


def test_npz_index_trajectory_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    traj = Trajectory(np.arange(4.0), random_poses(rng, 4), "x", "kitti", False)
    path = tmp_path / "p.out"  # a suffix other than .npz is kept as is
    write_npz_poses(path, traj)
    back = read_trajectory(path, "npz")
    assert not back.has_timestamps and back.names == ()
    assert PosesArtifact.load(path).header == {}
    assert [p.name for p in tmp_path.iterdir()] == ["p.out"]


def test_npz_plain(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 3)
    path = tmp_path / "plain.npz"
    np.savez(path, T_world_cam=T.astype(np.float32))
    traj = read_trajectory(path, "npz")
    assert not traj.has_timestamps
    np.testing.assert_allclose(traj.T_world_cam, T, atol=1e-6)
    np.savez(path, T_world_cam=T, timestamps=np.array([0.5, 1.0, 1.5]))
    traj = read_trajectory(path, "npz")
    assert traj.has_timestamps
    np.testing.assert_array_equal(traj.timestamps, [0.5, 1.0, 1.5])


def test_npz_extra_reserved_key(tmp_path: Path, rng: np.random.Generator) -> None:
    traj = Trajectory(np.arange(2.0), random_poses(rng, 2), "x", "kitti", False)
    with pytest.raises(ValueError, match="reserved"):
        write_npz_poses(tmp_path / "p.npz", traj, {"timestamps": np.zeros(2)})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("arrays", "pattern"),
    [
        (
            {"schema": np.array("acscal/joint"), "T_world_cam": np.eye(4)[None]},
            "acscal/joint artifact",
        ),
        (
            {
                "schema": np.array("acscal/poses"),
                "schema_version": np.array(2),
                "T_world_cam": np.eye(4)[None],
            },
            "newer acscal",
        ),
        ({"timestamps": np.zeros(1)}, "no 'T_world_cam'"),
        ({"T_world_cam": np.eye(4)}, "shape"),
        ({"T_world_cam": np.zeros((0, 4, 4))}, "shape"),
        ({"T_world_cam": np.array([["a"] * 4] * 4)[None]}, "numeric"),
        ({"T_world_cam": np.full((1, 4, 4), np.nan)}, "NaN"),
        ({"T_world_cam": 2 * np.eye(4)[None]}, "last row"),
        ({"T_world_cam": np.diag([1.0, 1.1, 1.0, 1.0])[None]}, "orthonormal"),
        ({"T_world_cam": np.eye(4)[None], "timestamps": np.zeros(2)}, "timestamps"),
        ({"T_world_cam": np.stack([np.eye(4)] * 2), "timestamps": np.ones(2)}, "increase"),
        ({"T_world_cam": np.eye(4)[None], "image_names": np.array([1])}, "image_names"),
    ],
)
def test_npz_malformed(tmp_path: Path, arrays: dict[str, np.ndarray], pattern: str) -> None:
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=pattern) as info:
        read_trajectory(path, "npz")
    assert info.value.path == str(path)


def test_npz_truncated_and_garbage(tmp_path: Path, rng: np.random.Generator) -> None:
    traj = Trajectory(np.arange(50.0), random_poses(rng, 50), "x", "kitti", False)
    good = tmp_path / "good.npz"
    write_npz_poses(good, traj)
    data = good.read_bytes()
    for k, blob in enumerate(
        [data[: len(data) // 2], data[:30], b"", b"hello", b"\x93NUMPY garbage"]
    ):
        path = tmp_path / f"bad{k}.npz"
        path.write_bytes(blob)
        with pytest.raises(InputError) as info:
            read_trajectory(path, "npz")
        assert info.value.path == str(path)
    npy = tmp_path / "single.npy"
    np.save(npy, np.eye(4)[None])
    with pytest.raises(InputError, match=r"single \.npy"):
        read_trajectory(npy, "npz")


# ----------------------------------------------------------------------------- dispatch


def test_read_trajectory_auto(tmp_path: Path, rng: np.random.Generator) -> None:
    T = random_poses(rng, 4)
    write_tum(tmp_path / "a.txt", np.arange(4.0), T)
    write_kitti(tmp_path / "b.txt", T)
    col = tmp_path / "model"
    col.mkdir()
    write_images_txt(col / "images.txt", [f"{k}.png" for k in range(4)], T)
    write_npz_poses(tmp_path / "c.npz", read_trajectory(tmp_path / "a.txt", "tum"))
    assert read_trajectory(tmp_path / "a.txt").format == "tum"
    assert read_trajectory(tmp_path / "b.txt").format == "kitti"
    assert read_trajectory(col).format == "colmap"
    assert read_trajectory(col / "images.txt").format == "colmap"
    assert read_trajectory(tmp_path / "c.npz").format == "npz"
    for fmt in ("tum", "kitti", "colmap", "npz"):
        src = {
            "tum": tmp_path / "a.txt",
            "kitti": tmp_path / "b.txt",
            "colmap": col,
            "npz": tmp_path / "c.npz",
        }[fmt]
        traj = read_trajectory(src, fmt)
        assert traj.format == fmt
        np.testing.assert_allclose(traj.T_world_cam, T, atol=1e-9)


def test_read_trajectory_errors(tmp_path: Path) -> None:
    path = tmp_path / "x.txt"
    path.write_text("# c\n1 2 3 4 5\n")
    with pytest.raises(InputError, match="cannot tell the trajectory format"):
        read_trajectory(path)
    with pytest.raises(InputError, match="unknown trajectory format"):
        read_trajectory(path, "csv")
    with pytest.raises(InputError, match="expected 8 numbers"):
        read_trajectory(path, "tum")
    path.write_text("")
    with pytest.raises(InputError, match="no poses"):
        read_trajectory(path)


# ----------------------------------------------------------------------------- Trajectory


def test_trajectory_validation() -> None:
    T = np.stack([np.eye(4)] * 3)
    with pytest.raises(InputError, match=re.escape("src: expected 3 timestamps")):
        Trajectory(np.arange(2.0), T, "src", "x", True)
    R_bad = T.copy()
    R_bad[:, :3, :3] *= 1.1
    with pytest.raises(InputError, match=r"src: .*not a rotation"):
        Trajectory(np.arange(3.0), R_bad, "src", "x", True)
    with pytest.raises(InputError, match="increase"):
        Trajectory(np.zeros(3), T, "src", "x", True)
    with pytest.raises(InputError, match="image names"):
        Trajectory(np.arange(3.0), T, "src", "x", True, names=("a",))
    with pytest.raises(InputError, match="no poses"):
        Trajectory(np.zeros(0), np.zeros((0, 4, 4)), "src", "x", True)
    traj = Trajectory(np.arange(3.0), T, "src", "x", True, names=("a", "b", "c"))
    sub = traj.select([0, 2])
    assert len(sub) == 2 and sub.names == ("a", "c")


# ----------------------------------------------------------------------------- fuzz


@settings(max_examples=examples(150))
@given(data=st.binary(max_size=300) | st.text(alphabet="0123456789.-e naif#\n\t", max_size=300))
def test_readers_raise_only_input_error(data: bytes | str) -> None:
    blob = data.encode() if isinstance(data, str) else data
    with tempfile.TemporaryDirectory() as d:
        for name, fmt in (
            ("t.txt", "tum"),
            ("k.txt", "kitti"),
            ("images.txt", "colmap"),
            ("p.npz", "npz"),
            ("auto.txt", "auto"),
        ):
            path = Path(d) / name
            path.write_bytes(blob)
            try:
                read_trajectory(path, fmt)
            except InputError as exc:
                assert "\n" not in str(exc)


def test_npz_quality_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    """Reprojection RMS and skipped images as `acscal poses` stores them; absent -> empty."""
    from acs_cli.io.trajectory import Trajectory, write_npz_poses

    T = Rotation.random(4, random_state=rng).as_matrix()
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, :3, :3] = T
    traj = Trajectory(np.arange(4.0), poses, source="t", format="npz", has_timestamps=True)
    full = tmp_path / "full.npz"
    write_npz_poses(
        full, traj, {"reprojection_rms": np.full(4, 0.2), "skipped_images": np.array(["x.png"])}
    )
    got = PosesArtifact.load(full)
    np.testing.assert_allclose(got.reprojection_rms, 0.2)
    assert got.skipped_images == ("x.png",)
    bare = tmp_path / "bare.npz"
    write_npz_poses(bare, traj)
    got = PosesArtifact.load(bare)
    assert got.reprojection_rms.size == 0 and got.skipped_images == ()
    with pytest.raises(InputError):
        PosesArtifact.load(tmp_path / "missing.npz")


def test_colmap_names_of_several_words_and_missing_points_lines(tmp_path: Path) -> None:
    """A name of three words makes an image line of 12 fields, which splits into triples: a
    file without POINTS2D lines must be refused, not read as every second image."""
    lines = [f"{k} 1 0 0 0 {0.1 * k} 0 0 1 my left image {k}.png" for k in (1, 2, 3, 4)]
    good = tmp_path / "images.txt"
    good.write_text("".join(f"{ln}\n\n" for ln in lines))
    assert read_trajectory(good, "colmap").names == tuple(
        f"my left image {k}.png" for k in (1, 2, 3, 4)
    )
    bad = tmp_path / "no_points.txt"
    bad.write_text("".join(f"{ln}\n" for ln in lines))
    with pytest.raises(InputError, match="POINTS2D"):
        read_trajectory(bad, "colmap")
