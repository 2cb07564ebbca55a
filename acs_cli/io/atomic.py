"""Safe file access: atomic writes, and bounded reads of regular files.

Writes go to a temporary file in the destination's folder, which is checked (every write
error, then flushed to disk) and renamed over the destination: a reader never sees a
half-written file, and a failed write (a full disk, a file-size limit) keeps the previous
file intact. A destination that is a symlink is written through (its target is replaced);
one that is a device, a FIFO or a socket is refused.

Reads (:func:`read_input_bytes`) accept only regular files of at most a stated size, so
``/dev/zero`` or a FIFO given as an input is an error, not an endless read.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import time
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path

from acs_cli.errors import InputError

__all__ = [
    "MAX_IMAGE_BYTES",
    "MAX_NPZ_BYTES",
    "MAX_NPZ_MEMBER_BYTES",
    "MAX_TEXT_BYTES",
    "MAX_YAML_BYTES",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_distinct_output",
    "check_writable",
    "input_size",
    "read_input_bytes",
    "resolve_output",
]

#: Largest YAML file (artifact, run config, target) acscal reads, bytes.
MAX_YAML_BYTES = 64 << 20
#: Largest text file (trajectory, timestamps) acscal reads, bytes.
MAX_TEXT_BYTES = 1 << 30
#: Largest image file acscal reads, bytes.
MAX_IMAGE_BYTES = 512 << 20
#: Largest NPZ file acscal reads, bytes.
MAX_NPZ_BYTES = 2 << 30
#: Largest array an NPZ may declare (its ``.npy`` header's shape times its item size),
#: bytes: a small compressed archive cannot make acscal allocate gigabytes.
MAX_NPZ_MEMBER_BYTES = 1 << 30


def _size_text(n: int) -> str:
    """``n`` bytes for a person: ``64 MiB``, ``1 GiB``, ``2.5 KiB``."""
    for unit, shift in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{n} bytes"


def _stat(path: Path, *, follow: bool = True) -> os.stat_result | None:
    """``path``'s status (``None`` if it does not exist); a symlink loop is an InputError."""
    try:
        return os.stat(path, follow_symlinks=follow)
    except FileNotFoundError:
        return None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            msg = "a symlink loop (too many levels of symbolic links)"
            raise InputError(msg, path=path) from exc
        if exc.errno == errno.ENOTDIR:
            return None  # a parent is a file: _prepare_parent names it
        raise InputError(f"cannot access ({exc.strerror or exc})", path=path) from exc


def resolve_output(path: str | Path) -> Path:
    """The file a write to ``path`` replaces: ``path``, or the target of a symlink.

    Raises
    ------
    InputError
        A symlink loop, or a destination that exists but is not a regular file (a device
        such as ``/dev/null``, a FIFO, a socket): acscal writes regular files only.
    """
    dest = Path(path)
    st = _stat(dest, follow=False)
    if st is not None and stat.S_ISLNK(st.st_mode):
        _stat(dest)  # a loop raises
        dest = Path(os.path.realpath(dest))
        st = _stat(dest, follow=False)
    if st is not None and not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        raise InputError(
            "cannot write: not a regular file (a device, FIFO or socket); give a file path",
            path=path,
        )
    return dest


def _prepare_parent(path: Path) -> None:
    """Create ``path``'s parent folders; refuse a destination that is a folder."""
    st = _stat(path)
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise InputError("cannot write: this is a folder, expected a file path", path=path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            f"cannot write: cannot create folder {path.parent} ({exc.strerror or exc})", path=path
        ) from exc


def _create_temp(path: Path, suffix: str) -> Path:
    """Create an empty, exclusive temporary file next to ``path`` (mode 0666 minus umask).

    Its name, ``.<name>.<pid>-<random>.tmp<suffix>``, carries the writer's process id, so
    a later write can recognise the leftovers of a killed writer (:func:`_remove_stale`).
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:12]}.tmp{suffix}")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise InputError(f"cannot write ({exc.strerror or exc})", path=path) from exc
    os.close(fd)
    return tmp


def _remove_quietly(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        tmp.unlink()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError, ValueError):  # no permission (alive) or a bogus pid
        return True
    return True


def _remove_stale(dest: Path) -> None:
    """Remove temporary files of ``dest`` left by writers that died (killed, power cut).

    Only files named by :func:`_create_temp` whose process id is no longer running on
    this machine are removed; a live writer's temporary file is left alone.
    """
    prefix = f".{dest.name}."
    try:
        entries = list(os.scandir(dest.parent))
    except OSError:
        return
    for entry in entries:
        name = entry.name
        if not name.startswith(prefix) or ".tmp" not in name[len(prefix) :]:
            continue
        pid_text = name[len(prefix) :].split("-", 1)[0]
        if pid_text.isdigit() and int(pid_text) != os.getpid() and not _pid_alive(int(pid_text)):
            _remove_quietly(Path(entry.path))


@contextlib.contextmanager
def atomic_path(path: str | Path, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path to write; rename it over ``path`` if the block succeeds.

    The temporary file lives in ``path``'s folder (so the rename is atomic) and has the
    same suffix, so writers that choose a format by extension (``np.savez``, matplotlib)
    can write to it. Parent folders are created. If the block raises, the temporary file
    is removed and an existing ``path`` is left intact; an ``OSError`` of the block (a
    full disk, a file-size limit) becomes an :class:`InputError` naming ``path``. The
    written file is flushed to disk (``fsync``) before the rename, so a late write error
    also keeps the old file. A symlink ``path`` is written through: its target is
    replaced (:func:`resolve_output`). After a successful rename, temporary files of
    ``path`` left by killed writers are removed.

    Parameters
    ----------
    path : str or Path
        The destination file.
    suffix : str, optional
        Suffix of the temporary file (default: ``path``'s suffix), e.g. ``".yaml"``.

    Yields
    ------
    Path
        The temporary file (already created, empty) to write.

    Raises
    ------
    InputError
        If the destination cannot be written (no permission, a folder, a device, a full
        disk, ...).
    """
    named = Path(path)
    dest = resolve_output(named)
    _prepare_parent(dest)
    tmp = _create_temp(dest, named.suffix if suffix is None else suffix)
    try:
        yield tmp
        _sync(tmp)
    except OSError as exc:
        _remove_quietly(tmp)
        raise InputError(f"cannot write ({exc.strerror or exc})", path=named) from exc
    except BaseException:
        _remove_quietly(tmp)
        raise
    try:
        os.replace(tmp, dest)
    except OSError as exc:
        _remove_quietly(tmp)
        raise InputError(f"cannot write ({exc.strerror or exc})", path=named) from exc
    _remove_stale(dest)


def _sync(tmp: Path) -> None:
    """Flush a written temporary file to disk; raise ``OSError`` when it cannot be (or
    when a writer left no regular file)."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EIO, "the written file is not a regular file")
        os.fsync(fd)
    finally:
        os.close(fd)


def check_writable(path: str | Path) -> None:
    """Fail early when ``path`` cannot be written (before a long computation, or before a
    command's first output when it writes several).

    Creates ``path``'s parent folders and a probe file beside it (removed at once); an
    existing ``path`` is not touched.

    Raises
    ------
    InputError
        The destination is a folder, a device, a FIFO or a symlink loop, its folder cannot
        be created, or no file can be created in it.
    """
    dest = resolve_output(path)
    _prepare_parent(dest)
    _remove_quietly(_create_temp(dest, ".probe"))


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file, checked size, fsync, rename).

    Raises
    ------
    InputError
        If the destination cannot be written (also: fewer bytes were written than given).
    """
    dest = Path(path)
    with atomic_path(dest) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            written = os.fstat(fh.fileno()).st_size
        if written != len(data):
            raise OSError(errno.EIO, f"wrote {written} of {len(data)} bytes")


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8, ``\\n`` line endings) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return os.path.realpath(a) == os.path.realpath(b)
    except (OSError, RuntimeError):  # RuntimeError: pathlib's report of a symlink loop
        return False


def check_distinct_output(output: str | Path, inputs: Iterable[str | Path]) -> None:
    """Refuse an output path that is one of the inputs (it would be overwritten).

    Parameters
    ----------
    output : str or Path
        The file about to be written.
    inputs : iterable of str or Path
        The files the command reads.

    Raises
    ------
    InputError
        If ``output`` resolves to the same file as any input (symlinks and hard links
        included).
    """
    out = Path(output)
    for inp in inputs:
        if _same_file(out, Path(inp)):
            raise InputError(
                f"the output would overwrite the input {inp}; choose another output path",
                path=out,
            )


def input_size(path: str | Path, what: str, max_bytes: int) -> int:
    """Check that ``path`` is a regular file of at most ``max_bytes``; return its size.

    Parameters
    ----------
    path : str or Path
        The input.
    what : str
        What it should be, for the messages (``"a trajectory"``).
    max_bytes : int
        The largest size accepted for this kind of input.

    Raises
    ------
    InputError
        No such file, a folder, a symlink loop, a device, FIFO or socket (``/dev/zero``, a
        pipe: never read), or a file larger than ``max_bytes``.
    """
    p = Path(path)
    st = _stat(p)
    if st is None:
        raise InputError("no such file", path=p)
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"is a folder, expected {what}", path=p)
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"not a regular file (a device, FIFO or socket), expected {what}", path=p)
    if st.st_size > max_bytes:
        raise InputError(
            f"is {_size_text(st.st_size)}, larger than the {_size_text(max_bytes)} acscal "
            f"reads as {what}",
            path=p,
        )
    return st.st_size


#: Digests of the files hashed in this process, by what identifies a file's version
#: (:func:`content_sha256`): a stage hashes its inputs for its cache keys and again for its
#: artifact's header.
_DIGESTS: dict[tuple[str, int, int, int, int, int], bytes] = {}
#: How long before its hashing a file must have been last modified for its digest to be
#: remembered (:func:`content_sha256`), nanoseconds.
SETTLED_NS = 2_000_000_000
#: Bytes :func:`content_sha256` reads at a time: memory stays bounded on a video of
#: gigabytes. 1 MiB chunks hashed 30 images of 1 MB in 47-49 ms, 2-8 MiB ones in 28-29 ms
#: (rwhe_kuka1).
HASH_CHUNK = 4 << 20


def content_sha256(path: str | Path) -> bytes:
    """SHA-256 (the raw digest) of a file's bytes, read in chunks of :data:`HASH_CHUNK`; a
    file hashed before in this process, unchanged since, is not read again.

    A file is the same when its device, inode, size, modification time and status-change
    time are (the last one no tool sets back: a copy that restores the modification time,
    ``cp -p`` or ``shutil.copy2``, still changes it). Only a file whose last change was more
    than :data:`SETTLED_NS` before its hashing is remembered: a file system stamps times in
    ticks of milliseconds, so a file rewritten within a tick of its hashing could keep them,
    as git's "racy" index entries do.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    import hashlib

    def key(st: os.stat_result) -> tuple[str, int, int, int, int, int]:
        return (os.fspath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)

    known = _DIGESTS.get(key(os.stat(path)))
    if known is not None:
        return known
    h = hashlib.sha256()
    with open(path, "rb", buffering=0) as fh:
        st = os.fstat(fh.fileno())  # the file read, whatever the path named before
        while chunk := fh.read(HASH_CHUNK):
            h.update(chunk)
    digest = h.digest()
    if time.time_ns() - max(st.st_mtime_ns, st.st_ctime_ns) <= SETTLED_NS:
        return digest
    if len(_DIGESTS) >= 100_000:  # a bound, for a process that hashes without end
        _DIGESTS.clear()
    _DIGESTS[key(st)] = digest
    return digest


def file_sha256(path: str | Path, what: str) -> str:
    """SHA-256 (hex) of a file's bytes (:func:`content_sha256`: a video of gigabytes too).

    Raises
    ------
    InputError
        Unreadable, naming it as ``what`` (``"image"``, ``"video"``).
    """
    try:
        return content_sha256(path).hex()
    except OSError as exc:
        raise InputError(f"cannot read {what} ({exc.strerror or exc})", path=path) from exc


def read_input_bytes(path: str | Path, what: str, max_bytes: int) -> bytes:
    """The content of a regular input file of at most ``max_bytes`` (see :func:`input_size`).

    At most ``max_bytes`` are read even if the file grows while it is read.

    Raises
    ------
    InputError
        As :func:`input_size`, or the file cannot be read.
    """
    p = Path(path)
    input_size(p, what, max_bytes)
    try:
        with open(p, "rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or exc})", path=p) from exc
    if len(data) > max_bytes:
        raise InputError(
            f"is larger than the {_size_text(max_bytes)} acscal reads as {what}", path=p
        )
    return data
