"""Fuzz every reader: random bytes and mutated valid files either read or raise InputError.

Each reader gets (1) random bytes, (2) byte-level mutations of a valid file (flip, insert,
delete, truncate, swap/duplicate lines, numbers replaced by nan/inf/huge values) and, for
the structured formats, (3) structural mutations (an NPZ array dropped, reshaped, retyped
or filled with NaN; a YAML node deleted or replaced by a value of another type). The only
exception allowed out of a reader is :class:`acs_cli.errors.InputError`, on one line.
"""

from __future__ import annotations

import copy
import io
import math
import re
import tempfile
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import cache, partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header, read_yaml_artifact, write_yaml_artifact
from acs_cli.io.detections import Detection, read_detections, write_detections
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.rig import RigArtifact, RigCameraResult, RigJointResult
from acs_cli.io.trajectory import (
    Trajectory,
    read_trajectory,
    write_kitti,
    write_npz_poses,
    write_tum,
)
from acs_cli.stages.export import run_export, run_rig_export
from acs_cli.stages.joint import read_joint
from acs_cli.stages.relpose import load_prior
from acs_cli.stages.run import STATE_FILE, load_run_config

#: ``make fuzz`` (``HYPOTHESIS_PROFILE=fuzz``) for fresh examples, ten times as many;
#: ``ACSCAL_FUZZ_SCALE=50`` for a longer soak (tests/hypothesis_profiles.py).
FUZZ = settings(
    max_examples=examples(200),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

# ----------------------------------------------------------------------------- valid seeds


def _poses(n: int, seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=rng).as_matrix()
    t = rng.uniform(-2, 2, size=(n, 3))
    return se3.transforms_from_rt(R, t).reshape(n, 4, 4)


def _header(kind: str) -> dict[str, Any]:
    return make_header(kind, {}, method="fuzz seed", units={"length": "m"}, frames={"a": "a"})


COLMAP_GOOD = """# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 3
1 1 0 0 0 0.1 0.2 0.3 1 img_001.png
10.5 20.5 -1 30 40 7
2 0.7071067811865476 0 0.7071067811865476 0 1 2 3 1 img_002.png

3 0.5 0.5 0.5 0.5 -1 0 2 1 sub/img_010.png
1 2 3
"""


@cache
def seeds() -> dict[str, bytes]:
    """One valid file of each kind, as bytes (built once)."""
    out: dict[str, bytes] = {}
    T = _poses(5)
    t = np.array([0.0, 0.1, 0.2, 0.35, 0.5])
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        write_tum(root / "a.tum", t, T)
        out["tum"] = (root / "a.tum").read_bytes()
        write_kitti(root / "a.kitti", T)
        out["kitti"] = (root / "a.kitti").read_bytes()
        out["colmap"] = COLMAP_GOOD.encode()
        traj = Trajectory(t, T, "x", "npz", True, names=tuple(f"img_{i}.png" for i in range(5)))
        corners = np.random.default_rng(1).uniform(0, 640, size=(5, 6, 2))
        board = np.zeros((6, 3))
        board[:, 0] = np.arange(6) * 0.025
        header = _header("poses") | {"intrinsics_file": "intrinsics.yaml"}
        write_npz_poses(
            root / "p.npz",
            traj,
            {
                "reprojection_rms": np.full(5, 0.1),
                "skipped_images": np.zeros(0, "<U1"),
                "corners": corners,
                "board_points": board,
            },
            header=header,
        )
        out["npz"] = (root / "p.npz").read_bytes()
        dets = {
            f"{i:064x}:9x6:v": Detection(
                f"img_{i}.png",
                i != 1,
                (640, 480),
                None if i == 1 else np.random.default_rng(i).uniform(0, 480, size=(54, 2)),
            )
            for i in range(3)
        }
        write_detections(root / "d.npz", dets)
        out["detections"] = (root / "d.npz").read_bytes()

        K = [[500.0, 0.0, 320.0], [0.0, 505.0, 240.0], [0.0, 0.0, 1.0]]
        write_yaml_artifact(
            root / "intrinsics.yaml",
            _header("intrinsics"),
            {
                "model": "pinhole",
                "image_size": [640, 480],
                "camera_matrix": K,
                "distortion": [0.01, -0.02, 0.0, 0.0, 0.0],
                "distortion_names": ["k1", "k2", "p1", "p2", "k3"],
                "rms_px": 0.1,
                "std": {"fx": 0.5},
                "board": {"cols": 9, "rows": 6, "square": 0.025, "units": "m"},
                "images": {"total": 2, "used": ["a.png", "b.png"]},
                "warnings": [],
            },
        )
        out["intrinsics"] = (root / "intrinsics.yaml").read_bytes()
        cov = (np.eye(3) * 1e-6).tolist()
        joint = {
            "position_in_a": [0.1, -0.2, 0.05],
            "position_in_a_std": [0.001, 0.001, 0.001],
            "position_in_b": [-0.1, 0.2, 0.03],
            "position_in_b_std": [0.001, 0.001, 0.001],
            "covariance_a": cov,
            "covariance_b": cov,
            "units": "m",
        }
        write_yaml_artifact(
            root / "joint.yaml",
            _header("joint"),
            {"scenario": "fixed_joint", "joint": joint, "quality": {"residual_rms": 0.01}},
        )
        out["joint"] = (root / "joint.yaml").read_bytes()
        T_b_a = _poses(1, 3)[0].tolist()
        write_yaml_artifact(
            root / "relpose.yaml",
            _header("relpose"),
            {
                "scenario": "general",
                "relative_pose": {
                    "T_b_a": T_b_a,
                    "rpy_deg": [1.0, 2.0, 3.0],
                    "translation_b_in_a": [0.1, 0.2, 0.3],
                    "reference": 0,
                },
                "joint": joint,
                "scale": {"phi_ba": 1.5},
            },
        )
        out["relpose"] = (root / "relpose.yaml").read_bytes()
        Tc = _poses(3, 5)
        Tc[0] = np.eye(4)
        cams = {
            c: RigCameraResult(c, Tc[i], np.full(3, 0.1), np.full(3, 0.001))
            for i, c in enumerate("abc")
        }
        cams["c"] = RigCameraResult(
            "c", Tc[2], np.full(3, 0.1), np.full(3, 0.001), True, 0.8, 0.01, _poses(1, 6)[0]
        )
        ball = RigJointResult(
            "ab", "ball", ("a", "b"), {"a": np.array([0.1, 0, 0]), "b": np.array([0, 0.1, 0])}
        )
        hinge = RigJointResult(
            "bc",
            "hinge",
            ("b", "c"),
            {"b": np.array([0.0, 0.2, 0.0]), "c": np.array([0.0, 0.0, 0.1])},
            {"b": np.full(3, 0.001), "c": np.full(3, 0.001)},
            {"b": np.array([1.0, 0.0, 0.0]), "c": np.array([0.0, 1.0, 0.0])},
            {"b": 0.5, "c": 0.5},
            residual_rms=0.01,
            frames_used=20,
        )
        rig = RigArtifact("a", 0, "m", cams, {"ab": ball, "bc": hinge}, header=_header("rig"))
        rig.save(root / "rig.yaml")
        out["rig"] = (root / "rig.yaml").read_bytes()
    out["run_config"] = b"""\
schema: acscal/run-config
schema_version: 1
output: ../run
board: {cols: 9, rows: 6, square: 0.025}
cameras:
  a: {images: ../images/fixed_joint/cam_a, model: pinhole}
  b: {images: ../images/fixed_joint/cam_b}
intrinsics: {from: all}
joint: {scenario: fixed_joint, method: refined}
relpose:
  images: {a: ../images/general/cam_a, b: ../images/general/cam_b}
  method: refined
  unknown_scale: false
  self_calibrate: false
  reference: 0
workers: 2
"""
    out["run_state"] = b"""\
schema: acscal/run-state
schema_version: 1
tool: {name: acscal, version: 0.1.0}
config: /x/run.yaml
stages:
  intrinsics a:
    stamp: abc
    options_sha256: def
    options: {cols: 9, rows: 6}
    inputs: {images_joint: {path: /x, sha256: '00'}}
    outputs: {cam_a/intrinsics.yaml: '11'}
"""
    return out


def test_seeds_are_valid() -> None:
    """The unmutated seeds read (so the mutations below start from valid files)."""
    s = seeds()
    with tempfile.TemporaryDirectory() as d:
        for key, name, read in READERS:
            path = Path(d) / name
            path.write_bytes(s[key])
            read(path)
    assert read_detections_strict_len(s["detections"]) == 3


def read_detections_strict_len(blob: bytes) -> int:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.detections.npz"
        p.write_bytes(blob)
        return len(read_detections(p))


# ----------------------------------------------------------------------------- readers


def _export_opencv(path: Path) -> None:
    # the seed has unknown scale: metres need an explicit --scale
    run_export(path, path.with_name("out_cv.yaml"), "opencv", scale=1.0)


def _export_kalibr(path: Path) -> None:
    intr = path.with_name("seed_intrinsics.yaml")  # Kalibr needs every camera's intrinsics
    intr.write_bytes(seeds()["intrinsics"])
    cams = {"a": intr, "b": intr}
    run_export(path, path.with_name("out_chain.yaml"), "kalibr", intrinsics=cams, scale=1.0)


def _read_detections(path: Path) -> None:
    got = read_detections(path)  # documented: never raises, a bad cache reads as empty
    assert isinstance(got, dict)
    for det in got.values():
        assert isinstance(det, Detection)
        if det.found:
            assert det.corners is not None and np.all(np.isfinite(det.corners))


def _check_state(path: Path) -> None:
    from acs_cli.stages import run as run_stage

    got = run_stage._read_state(path)  # a damaged state file means: rerun every stage
    assert isinstance(got, dict)


def _rig_urdf(path: Path) -> None:
    run_rig_export(path, path.with_name("rig.urdf"), "urdf")


def _rig_kalibr(path: Path) -> None:
    intr = path.with_name("seed_intrinsics.yaml")
    intr.write_bytes(seeds()["intrinsics"])
    cams = dict.fromkeys("abc", intr)
    run_rig_export(path, path.with_name("rig_chain.yaml"), "kalibr", intrinsics=cams)


def _joint_prior(path: Path) -> None:
    load_prior(path, metric=False)


def _run_config(path: Path) -> None:
    load_run_config(path)


# (seed key, file name, reader)
READERS: list[tuple[str, str, Callable[[Path], Any]]] = [
    ("tum", "traj.tum", partial(read_trajectory, fmt="tum")),
    ("tum", "traj.txt", read_trajectory),
    ("kitti", "traj.kitti", partial(read_trajectory, fmt="kitti")),
    ("kitti", "kitti.txt", read_trajectory),
    ("colmap", "images.txt", partial(read_trajectory, fmt="colmap")),
    ("colmap", "images.txt", read_trajectory),
    ("npz", "poses.npz", partial(read_trajectory, fmt="npz")),
    ("npz", "poses.npz", read_trajectory),
    ("npz", "poses.npz", PosesArtifact.load),
    ("detections", "x.detections.npz", _read_detections),
    ("run_config", "run.yaml", _run_config),
    ("run_state", STATE_FILE, _check_state),
    ("intrinsics", "intrinsics.yaml", IntrinsicsArtifact.load),
    ("intrinsics", "intrinsics.yaml", lambda p: read_yaml_artifact(p, "intrinsics", ["model"])),
    ("joint", "joint.yaml", read_joint),
    ("joint", "joint.yaml", _joint_prior),
    ("relpose", "relpose.yaml", read_joint),
    ("relpose", "relpose.yaml", _export_opencv),
    ("relpose", "relpose.yaml", _export_kalibr),
    ("rig", "rig.yaml", RigArtifact.load),
    ("rig", "rig.yaml", _rig_urdf),
    ("rig", "rig.yaml", _rig_kalibr),
]


KINDS = sorted({k for k, _, _ in READERS})
TEXT_KINDS = [k for k in KINDS if k not in ("npz", "detections")]
NPZ_KINDS = ["npz", "detections"]
YAML_KINDS = ["run_config", "run_state", "intrinsics", "joint", "relpose", "rig"]


def _readers_of(kind: str) -> list[tuple[str, Callable[[Path], Any]]]:
    return [(name, read) for k, name, read in READERS if k == kind]


@contextmanager
def _file(name: str, blob: bytes) -> Iterator[Path]:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / name
        path.write_bytes(blob)
        yield path


def _only_input_error(kind: str, blob: bytes) -> None:
    """Every reader of ``kind`` reads ``blob`` or raises a one-line InputError."""
    for name, read in _readers_of(kind):
        with _file(name, blob) as path:
            try:
                read(path)
            except InputError as exc:
                text = str(exc)
                assert "\n" not in text and text.strip(), repr(text)


# ----------------------------------------------------------------------------- mutations

NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
WEIRD_NUMBERS = [
    b"nan",
    b"NaN",
    b"inf",
    b"-inf",
    b".nan",
    b".inf",
    b"1e308",
    b"-1e308",
    b"1e200",
    b"1e25",
    b"1e999",
    b"1e-320",
    b"5e-324",
    b"-1e-308",
    b"0",
    b"-0",
    b"99999999999999999999999999999",
    b"0x10",
    b"1_000",
    b"",
    b"1.2.3",
]

byte_op = st.one_of(
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 7)),
    st.tuples(st.just("insert"), st.floats(0, 1), st.binary(min_size=1, max_size=8)),
    st.tuples(
        st.just("insert"),
        st.floats(0, 1),
        st.sampled_from([b"\n", b" ", b"#", b"\x00", b"\xff", b":", b"- ", b"{", b"[", b"\t"]),
    ),
    st.tuples(st.just("delete"), st.floats(0, 1), st.integers(1, 16)),
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("swap_lines"), st.integers(0, 40), st.integers(0, 40)),
    st.tuples(st.just("dup_line"), st.integers(0, 40)),
    st.tuples(st.just("drop_line"), st.integers(0, 40)),
    st.tuples(st.just("number"), st.integers(0, 200), st.sampled_from(WEIRD_NUMBERS)),
)


def apply_byte_ops(blob: bytes, ops: list[tuple[Any, ...]]) -> bytes:
    data = bytearray(blob)
    for op in ops:
        kind = op[0]
        n = len(data)
        if kind == "flip" and n:
            i = min(int(op[1] * n), n - 1)
            data[i] ^= 1 << op[2]
        elif kind == "insert":
            i = int(op[1] * n)
            data[i:i] = op[2]
        elif kind == "delete" and n:
            i = min(int(op[1] * n), n - 1)
            del data[i : i + op[2]]
        elif kind == "truncate":
            del data[int(op[1] * n) :]
        elif kind in ("swap_lines", "dup_line", "drop_line"):
            lines = bytes(data).split(b"\n")
            i = op[1] % len(lines)
            if kind == "swap_lines":
                j = op[2] % len(lines)
                lines[i], lines[j] = lines[j], lines[i]
            elif kind == "dup_line":
                lines.insert(i, lines[i])
            else:
                del lines[i]
            data = bytearray(b"\n".join(lines))
        elif kind == "number":
            found = list(NUMBER.finditer(bytes(data)))
            if found:
                m = found[op[1] % len(found)]
                data[m.start() : m.end()] = op[2]
    return bytes(data)


# ----------------------------------------------------------------------------- random bytes


@FUZZ
@given(
    kind=st.sampled_from(KINDS),
    data=st.binary(max_size=400)
    | st.text(alphabet="0123456789.-+eE naif#:{}[],'\"\n\t", max_size=400).map(str.encode),
)
def test_random_bytes(kind: str, data: bytes) -> None:
    _only_input_error(kind, data)


# ----------------------------------------------------------------------------- byte mutations


@FUZZ
@given(kind=st.sampled_from(TEXT_KINDS), ops=st.lists(byte_op, min_size=1, max_size=4))
def test_mutated_text_files(kind: str, ops: list[tuple[Any, ...]]) -> None:
    _only_input_error(kind, apply_byte_ops(seeds()[kind], ops))


@settings(FUZZ, max_examples=examples(100))
@given(kind=st.sampled_from(NPZ_KINDS), ops=st.lists(byte_op, min_size=1, max_size=3))
def test_mutated_npz_bytes(kind: str, ops: list[tuple[Any, ...]]) -> None:
    _only_input_error(kind, apply_byte_ops(seeds()[kind], ops))


# ----------------------------------------------------------------------------- NPZ structure


def _npz_arrays(blob: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(blob), allow_pickle=False) as z:
        return {k: np.asarray(z[k]) for k in z.files}


REPLACEMENTS: list[Callable[[np.ndarray], Any]] = [
    lambda a: np.array("acscal/poses"),
    lambda a: np.array("acscal/detections"),
    lambda a: np.array("something/else"),
    lambda a: np.array(7, dtype=np.int64),
    lambda a: np.array(-1, dtype=np.int64),
    lambda a: np.array(2**62, dtype=np.int64),
    lambda a: np.array(1.5),
    lambda a: np.array(True),
    lambda a: np.zeros(0),
    lambda a: np.zeros((0, 4, 4)),
    lambda a: np.zeros((2, 2)),
    lambda a: np.array(["a", "b"]),
    lambda a: np.array([b"x", b"\xff"]),
    lambda a: np.array([1 + 2j, 3j]),
    lambda a: np.array([None, 1], dtype=object),
    lambda a: np.array("{not json"),
    lambda a: np.array("[1, 2]"),
    lambda a: np.array('{"intrinsics_file": 3}'),
    lambda a: a.ravel(),
    lambda a: a.reshape(-1, 1) if a.size else a,
    lambda a: a.T,
    lambda a: a[:1] if a.ndim else a,
    lambda a: a[1:] if a.ndim else a,
    lambda a: np.concatenate([a, a]) if a.ndim else a,
    lambda a: a.astype(np.float32) if a.dtype.kind in "biuf" else a,
    lambda a: a.astype(np.int64) if a.dtype.kind in "biuf" else a,
    lambda a: a.astype(bool) if a.dtype.kind in "biuf" else a,
    # bytes decoded as Latin-1 (astype(str) decodes ASCII and fails on b"\xff")
    lambda a: np.char.decode(a, "latin-1") if a.dtype.kind == "S" else a.astype(str),
    lambda a: np.full(a.shape, np.nan),
    lambda a: np.full(a.shape, np.inf),
    lambda a: np.full(a.shape, 1e308),
    lambda a: np.full(a.shape, -1, dtype=np.int64),
    lambda a: np.full(a.shape, 10**9, dtype=np.int64),
    lambda a: np.zeros(a.shape),
    lambda a: a * 1.01 if a.dtype.kind == "f" else a,
]


@settings(FUZZ, max_examples=examples(300))
@given(
    kind=st.sampled_from(NPZ_KINDS),
    edits=st.lists(
        st.tuples(
            st.integers(0, 50),
            st.one_of(st.just(-1), st.integers(0, len(REPLACEMENTS) - 1)),
            st.one_of(st.none(), st.integers(0, 10_000)),
        ),
        min_size=1,
        max_size=3,
    ),
    extra=st.booleans(),
)
def test_mutated_npz_arrays(
    kind: str, edits: list[tuple[int, int, int | None]], extra: bool
) -> None:
    arrays = _npz_arrays(seeds()[kind])
    for key_i, repl_i, pos in edits:
        keys = sorted(arrays)
        if not keys:
            break
        key = keys[key_i % len(keys)]
        if repl_i < 0:
            del arrays[key]
        elif pos is not None and arrays[key].dtype.kind == "f" and arrays[key].size:
            a = arrays[key].copy()
            with np.errstate(over="ignore"):  # 1e308 into a float32 array is inf
                a.flat[pos % a.size] = [np.nan, np.inf, -np.inf, 1e308, 0.0][pos % 5]
            arrays[key] = a
        else:
            with np.errstate(all="ignore"):  # casting NaN to int is the point here
                arrays[key] = np.asarray(REPLACEMENTS[repl_i](arrays[key]))
    if extra:
        arrays["unexpected"] = np.arange(3)
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    _only_input_error(kind, buf.getvalue())


def test_npz_edge_archives() -> None:
    """Archives that are not quite NPZ: a bare .npy, an empty zip, a zip of text."""
    buf = io.BytesIO()
    np.save(buf, np.eye(4))
    empty = io.BytesIO()
    with zipfile.ZipFile(empty, "w"):
        pass
    texty = io.BytesIO()
    with zipfile.ZipFile(texty, "w") as z:
        z.writestr("T_world_cam.npy", b"not an npy")
        z.writestr("schema.npy", b"\x93NUMPY")
    for blob in (buf.getvalue(), empty.getvalue(), texty.getvalue(), b"PK\x03\x04"):
        for kind in NPZ_KINDS:
            _only_input_error(kind, blob)


# ----------------------------------------------------------------------------- YAML structure

WEIRD_VALUES: list[Any] = [
    None,
    "",
    "x",
    "acscal/joint",
    -1,
    0,
    1,
    2,
    10**30,
    1e308,
    -1e308,
    1e25,
    1e-308,
    5e-324,
    math.nan,
    math.inf,
    -math.inf,
    True,
    [],
    {},
    [1, 2],
    [[1, 2], [3, 4]],
    [[math.nan] * 3] * 3,
    [[1e308] * 4] * 4,
    [[1e-300, 1e10, 0], [1e10, 1e-300, 0], [0, 0, 1e-300]],
    [None, None, None],
    ["a", "b", "c"],
    [[1, 2, 3], [4, 5]],
    {"a": 1},
    [[[1]]],
    "2024-01-01",
]


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    found = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            found += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            found += _paths(v, (*prefix, i))
    return found


def _set(doc: Any, path: tuple[Any, ...], op: str, value: Any) -> Any:
    if not path:
        return value if op == "replace" else doc
    parent = doc
    for part in path[:-1]:
        parent = parent[part]
    last = path[-1]
    if op == "delete":
        del parent[last]
    elif op == "replace":
        parent[last] = value
    elif op == "wrap":
        parent[last] = [parent[last]]
    return doc


@settings(FUZZ, max_examples=examples(300))
@given(
    kind=st.sampled_from(YAML_KINDS),
    edits=st.lists(
        st.tuples(
            st.integers(0, 500),
            st.sampled_from(["delete", "replace", "replace", "wrap"]),
            st.sampled_from(range(len(WEIRD_VALUES))),
        ),
        min_size=1,
        max_size=3,
    ),
)
def test_mutated_yaml_structure(kind: str, edits: list[tuple[int, str, int]]) -> None:
    doc = yaml.safe_load(seeds()[kind])
    for where, op, value_i in edits:
        paths = _paths(doc)
        path = paths[where % len(paths)]
        if op == "delete" and not path:
            continue
        doc = _set(doc, path, op, copy.deepcopy(WEIRD_VALUES[value_i]))
    text = yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
    _only_input_error(kind, text.encode())


@pytest.mark.parametrize("kind", YAML_KINDS)
def test_yaml_edge_documents(kind: str) -> None:
    """YAML that parses to odd things: deep nesting, anchors, tags, multiple documents."""
    blobs = [
        b"[" * 2000 + b"]" * 2000,
        b"a: &x [*x]\n",
        b"!!python/object:os.system {}\n",
        b"--- 1\n--- 2\n",
        b"%YAML:1.0\n---\nT_b_a: !!opencv-matrix\n  rows: 4\n",
        b"\xef\xbb\xbfschema: acscal/joint\n",
        b"\x00\x00\xfe\xff",
        b"key: value\n" * 3,
        b"? [a, b]\n: c\n",
        b"{1: 2, [3]: 4}\n",
    ]
    for blob in blobs:
        _only_input_error(kind, blob)
