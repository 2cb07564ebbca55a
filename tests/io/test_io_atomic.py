"""Atomic writes and output/input clash detection."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from acs_cli.errors import InputError
from acs_cli.io.atomic import (
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    check_distinct_output,
)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_write_text_creates_parents(tmp_path: Path) -> None:
    dest = tmp_path / "a" / "b" / "out.txt"
    atomic_write_text(dest, "hello\n")
    assert dest.read_text() == "hello\n"
    assert _leftovers(dest.parent) == []


def test_write_bytes_replaces(tmp_path: Path) -> None:
    dest = tmp_path / "out.bin"
    dest.write_bytes(b"old")
    atomic_write_bytes(dest, b"new")
    assert dest.read_bytes() == b"new"


def test_atomic_path_same_suffix_and_rename(tmp_path: Path) -> None:
    dest = tmp_path / "poses.npz"
    with atomic_path(dest) as tmp:
        assert tmp.parent == tmp_path
        assert tmp.suffix == ".npz"
        assert tmp != dest
        np.savez(tmp, x=np.arange(3))
    assert not tmp.exists()
    with np.load(dest) as z:
        assert z["x"].tolist() == [0, 1, 2]
    assert _leftovers(tmp_path) == []


def test_atomic_path_suffix_override(tmp_path: Path) -> None:
    with atomic_path(tmp_path / "calib.txt", suffix=".yaml") as tmp:
        assert tmp.suffix == ".yaml"
        tmp.write_text("x: 1\n")
    assert (tmp_path / "calib.txt").read_text() == "x: 1\n"


def test_failed_block_leaves_no_file(tmp_path: Path) -> None:
    dest = tmp_path / "out.txt"
    with pytest.raises(RuntimeError), atomic_path(dest) as tmp:
        tmp.write_text("partial")
        raise RuntimeError("boom")
    assert not dest.exists()
    assert list(tmp_path.iterdir()) == []


def test_failed_block_keeps_existing_file(tmp_path: Path) -> None:
    dest = tmp_path / "out.txt"
    dest.write_text("precious")
    with pytest.raises(ValueError), atomic_path(dest) as tmp:
        tmp.write_text("partial")
        raise ValueError("boom")
    assert dest.read_text() == "precious"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_destination_is_folder(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="folder"):
        atomic_write_text(tmp_path, "x")


def test_parent_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match="cannot write") as info:
        atomic_write_text(tmp_path / "f" / "out.txt", "x")
    assert info.value.path == str(tmp_path / "f" / "out.txt")


@pytest.mark.skipif(
    sys.platform == "win32" or (hasattr(os, "geteuid") and os.geteuid() == 0),
    reason="permissions are not enforced",
)
def test_not_writable_folder(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(InputError, match="cannot write"):
            atomic_write_text(ro / "out.txt", "x")
    finally:
        ro.chmod(0o700)


def test_check_distinct_output(tmp_path: Path) -> None:
    a = tmp_path / "a.txt"
    a.write_text("x")
    check_distinct_output(tmp_path / "b.txt", [a])
    with pytest.raises(InputError, match="overwrite the input"):
        check_distinct_output(a, [tmp_path / "other.txt", a])
    with pytest.raises(InputError):
        check_distinct_output(tmp_path / "sub" / ".." / "a.txt", [a])
    link = tmp_path / "link.txt"
    link.symlink_to(a)
    with pytest.raises(InputError):
        check_distinct_output(link, [a])
    # the output not existing yet but named like an input
    with pytest.raises(InputError):
        check_distinct_output(tmp_path / "new.txt", [tmp_path / "new.txt"])
