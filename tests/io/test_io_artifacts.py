"""YAML artifacts: header, round trip and the errors of reading the wrong file."""

from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples

import acs_cli
from acs_cli.errors import InputError
from acs_cli.io.artifacts import (
    SCHEMA_VERSION,
    get_path,
    make_header,
    read_yaml_artifact,
    sha256_of,
    to_plain,
    write_yaml_artifact,
)


def _header(tmp_path: Path, kind: str = "joint") -> dict[str, object]:
    traj = tmp_path / "a.txt"
    traj.write_text("1 0 0 0 0 0 0 1\n")
    return make_header(
        kind,
        {"traj_a": traj},
        method="pivot least squares",
        units={"length": "A units", "angles": "deg"},
        frames={"joint.position_in_a": "a"},
    )


def test_header(tmp_path: Path) -> None:
    h = _header(tmp_path)
    assert h["schema"] == "acscal/joint"
    assert h["schema_version"] == SCHEMA_VERSION
    assert h["tool"] == {"name": "acscal", "version": acs_cli.__version__}
    created = datetime.fromisoformat(str(h["created"]).replace("Z", "+00:00"))
    assert created.utcoffset() is not None and created.utcoffset().total_seconds() == 0  # type: ignore[union-attr]
    digest = hashlib.sha256(b"1 0 0 0 0 0 0 1\n").hexdigest()
    assert h["inputs"] == {"traj_a": {"path": str(tmp_path / "a.txt"), "sha256": digest}}
    assert list(h) == [
        "schema",
        "schema_version",
        "tool",
        "created",
        "inputs",
        "method",
        "units",
        "frames",
    ]


def test_sha256_of_folder(tmp_path: Path) -> None:
    d = tmp_path / "imgs"
    (d / "sub").mkdir(parents=True)
    (d / "b.png").write_bytes(b"bb")
    (d / "sub" / "a.png").write_bytes(b"aa")
    h1 = sha256_of(d)
    assert h1 == sha256_of(d)
    (d / "b.png").write_bytes(b"bc")
    assert sha256_of(d) != h1
    (d / "b.png").write_bytes(b"bb")
    assert sha256_of(d) == h1
    (d / "b.png").rename(d / "c.png")
    assert sha256_of(d) != h1
    with pytest.raises(InputError, match="no such file"):
        sha256_of(tmp_path / "missing")


def test_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    header = _header(tmp_path)
    T = rng.normal(size=(4, 4))
    body = {
        "joint": {
            "position_in_a": rng.normal(size=3),
            "position_in_a_std": np.float64(0.01),
            "n_frames": np.int64(42),
            "ok": np.bool_(True),
        },
        "relative_pose": {"T_b_a": T, "label": np.str_("x")},
        "tuple": (1, 2.5),
        "path": tmp_path,
    }
    path = tmp_path / "out" / "joint.yaml"
    write_yaml_artifact(path, header, body)
    doc = read_yaml_artifact(path, "joint", required=["joint.position_in_a", "relative_pose.T_b_a"])
    assert doc["schema"] == "acscal/joint"
    np.testing.assert_array_equal(doc["relative_pose"]["T_b_a"], T)
    np.testing.assert_array_equal(doc["joint"]["position_in_a"], body["joint"]["position_in_a"])  # type: ignore[index]
    assert doc["joint"]["n_frames"] == 42 and doc["joint"]["ok"] is True
    assert doc["tuple"] == [1, 2.5] and doc["path"] == str(tmp_path)
    assert get_path(doc, "joint.position_in_a_std") == 0.01
    assert get_path(doc, "joint.nope", None) is None
    text = path.read_text()
    assert text.startswith("schema: acscal/joint\n")
    assert "!!" not in text  # plain YAML, no python tags


def test_body_clashes_with_header(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="clash"):
        write_yaml_artifact(tmp_path / "x.yaml", _header(tmp_path), {"schema": 1})


def test_to_plain() -> None:
    @dataclass
    class D:
        a: np.ndarray

    assert to_plain(D(np.arange(2))) == {"a": [0, 1]}
    assert to_plain({1: np.float32(0.5)}) == {"1": 0.5}
    with pytest.raises(TypeError):
        to_plain(object())


def test_get_path_missing() -> None:
    with pytest.raises(InputError, match=r"missing key 'a\.b\.c'") as info:
        get_path({"a": {"b": 1}}, "a.b.c", source="f.yaml")
    assert str(info.value).startswith("f.yaml: ")


@pytest.mark.parametrize(
    ("text", "pattern", "line"),
    [
        ("a: [1, 2\nb: 3\n", "not valid YAML", 2),
        ("key: value\n  bad: indent\n", "not valid YAML", 2),
        ("- 1\n- 2\n", "expected a YAML mapping, got list", None),
        ("", "expected a YAML mapping, got NoneType", None),
        ("just text\n", "expected a YAML mapping", None),
        ("a: 1\n", "no 'schema' key", None),
        (
            "schema: acscal/poses\nschema_version: 1\n",
            "this is a acscal/poses artifact, expected acscal/joint",
            None,
        ),
        ("schema: acscal/joint\nschema_version: 2\n", "written by a newer acscal", None),
        ("schema: acscal/joint\nschema_version: one\n", "must be an integer", None),
        (
            "schema: acscal/joint\nschema_version: 1\njoint: {}\n",
            "missing key 'joint.position_in_a'",
            None,
        ),
        (
            "schema: acscal/joint\nschema_version: 1\njoint: 3\n",
            "missing key 'joint.position_in_a'",
            None,
        ),
    ],
)
def test_read_errors(tmp_path: Path, text: str, pattern: str, line: int | None) -> None:
    path = tmp_path / "a.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=pattern) as info:
        read_yaml_artifact(path, "joint", required=["joint.position_in_a"])
    assert info.value.path == str(path)
    assert info.value.line == line
    assert "\n" not in str(info.value)


def test_read_missing_and_binary(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_yaml_artifact(tmp_path / "nope.yaml", "joint")
    with pytest.raises(InputError, match="folder"):
        read_yaml_artifact(tmp_path, "joint")
    path = tmp_path / "b.yaml"
    path.write_bytes(b"\xff\xfe\x00garbage\x00\x01")
    with pytest.raises(InputError):
        read_yaml_artifact(path, "joint")


def test_read_accepts_older_or_equal_version(tmp_path: Path) -> None:
    path = tmp_path / "a.yaml"
    path.write_text(yaml.safe_dump({"schema": "acscal/joint", "schema_version": 0}))
    assert read_yaml_artifact(path, "joint")["schema_version"] == 0


@settings(max_examples=examples(150))
@given(data=st.binary(max_size=200) | st.text(max_size=200))
def test_reader_raises_only_input_error(data: bytes | str) -> None:
    blob = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "a.yaml"
        path.write_bytes(blob)
        try:
            read_yaml_artifact(path, "joint", required=["x.y"])
        except InputError as exc:
            assert "\n" not in str(exc)


def test_a_repeated_key_is_refused_naming_its_line(tmp_path: Path) -> None:
    """YAML forbids a key twice in one mapping; PyYAML would keep the last value silently
    (a run config's second `square:` would win). Merge keys (`<<`) are not repeats."""
    from acs_cli.io.artifacts import load_yaml_file

    f = tmp_path / "run.yaml"
    f.write_text("board:\n  cols: 9\n  rows: 6\n  cols: 8\n")
    with pytest.raises(InputError, match="duplicate key 'cols' \\(first on line 2\\)") as err:
        load_yaml_file(f)
    assert err.value.line == 4
    f.write_text("a: {b: 1, b: 2}\n")
    with pytest.raises(InputError, match="duplicate key 'b'"):
        load_yaml_file(f)
    f.write_text("base: &b {x: 1, y: 2}\nuse:\n  <<: *b\n  y: 3\n")
    assert load_yaml_file(f) == {"base": {"x": 1, "y": 2}, "use": {"x": 1, "y": 3}}
