"""Atomic writes and output/input clash detection."""

from __future__ import annotations

import errno
import os
import stat
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
    check_writable,
    read_input_bytes,
    resolve_output,
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


# --------------------------------------------------------------------------------------
# Destinations that are not plain files; write errors; bounded reads


def test_a_symlink_destination_is_written_through(tmp_path: Path) -> None:
    target = tmp_path / "t" / "real.txt"
    target.parent.mkdir()
    target.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    atomic_write_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"
    assert resolve_output(link) == Path(os.path.realpath(target))
    dangling = tmp_path / "dangling.txt"
    dangling.symlink_to(tmp_path / "t" / "later.txt")
    atomic_write_text(dangling, "x")
    assert dangling.is_symlink() and (tmp_path / "t" / "later.txt").read_text() == "x"


def test_a_fifo_or_a_symlink_loop_is_never_replaced(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        atomic_write_text(fifo, "x")
    with pytest.raises(InputError, match="not a regular file"):
        check_writable(fifo)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(InputError, match="symlink loop"):
        atomic_write_text(loop, "x")
    with pytest.raises(InputError, match="symlink loop"):
        check_writable(loop)
    check_distinct_output(tmp_path / "out.txt", [loop])  # no RuntimeError from pathlib
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "loop"]


def test_a_write_error_in_the_block_keeps_the_old_file(tmp_path: Path) -> None:
    dest = tmp_path / "out.npz"
    dest.write_text("precious")
    with (
        pytest.raises(InputError, match=r"cannot write \(No space left") as info,
        atomic_path(dest) as tmp,
    ):
        tmp.write_text("partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert info.value.path == str(dest)
    assert dest.read_text() == "precious"
    assert [p.name for p in tmp_path.iterdir()] == ["out.npz"]


def test_read_input_bytes_refuses_what_is_not_a_bounded_regular_file(tmp_path: Path) -> None:
    f = tmp_path / "a.txt"
    f.write_bytes(b"x" * 100)
    assert read_input_bytes(f, "a text", 100) == b"x" * 100
    with pytest.raises(InputError, match="larger than the 50 bytes acscal reads as a text"):
        read_input_bytes(f, "a text", 50)
    with pytest.raises(InputError, match="is a folder, expected a text"):
        read_input_bytes(tmp_path, "a text", 100)
    with pytest.raises(InputError, match="no such file"):
        read_input_bytes(tmp_path / "missing", "a text", 100)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        read_input_bytes(fifo, "a text", 100)  # would block without the check
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(InputError, match="symlink loop"):
        read_input_bytes(loop, "a text", 100)


def test_a_settled_file_is_hashed_once_and_a_changed_one_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import hashlib

    from acs_cli.io import atomic

    def sha(data: bytes) -> str:
        return hashlib.sha256(data).hexdigest()

    f = tmp_path / "img.png"
    f.write_bytes(b"a" * 1000)
    old = 1_000_000_000_000_000_000  # 2001
    os.utime(f, ns=(old, old))
    opened: list[str] = []
    real_open = open
    monkeypatch.setattr(
        "builtins.open", lambda p, *a, **k: opened.append(str(p)) or real_open(p, *a, **k)
    )
    # a file changed just now (its status-change time) is hashed, not remembered: a
    # rewrite within the clock's tick could keep its times
    assert atomic.file_sha256(f, "image") == sha(b"a" * 1000)
    assert atomic.file_sha256(f, "image") == sha(b"a" * 1000)
    assert len(opened) == 2
    # settled (every change long enough ago): remembered
    monkeypatch.setattr(atomic, "SETTLED_NS", -(10**19))
    opened.clear()
    assert atomic.file_sha256(f, "image") == sha(b"a" * 1000)
    assert atomic.file_sha256(f, "image") == sha(b"a" * 1000)
    assert len(opened) == 1
    # rewritten at the same size and inode, its modification time put back (cp -p,
    # shutil.copy2): the status-change time tells
    f.write_bytes(b"b" * 1000)
    os.utime(f, ns=(old, old))
    assert atomic.file_sha256(f, "image") == sha(b"b" * 1000)
