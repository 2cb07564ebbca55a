"""Atomic file writes: write a temporary file in the destination's folder, then rename it.

A reader never sees a half-written file, and a failed write keeps the previous file intact.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path

from acs_cli.errors import InputError

__all__ = [
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_distinct_output",
    "check_writable",
]


def _prepare_parent(path: Path) -> None:
    """Create ``path``'s parent folders; refuse a destination that is a folder."""
    if path.is_dir():
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
    same suffix, so writers that choose a format by extension (``np.savez``,
    ``cv2.FileStorage``, matplotlib) can write to it. Parent folders are created. If the
    block raises, the temporary file is removed and an existing ``path`` is left intact.
    After a successful rename, temporary files of ``path`` left by killed writers are
    removed.

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
        If the destination cannot be written (no permission, a folder, ...).
    """
    dest = Path(path)
    _prepare_parent(dest)
    tmp = _create_temp(dest, dest.suffix if suffix is None else suffix)
    try:
        yield tmp
    except BaseException:
        _remove_quietly(tmp)
        raise
    try:
        os.replace(tmp, dest)
    except OSError as exc:
        _remove_quietly(tmp)
        raise InputError(f"cannot write ({exc.strerror or exc})", path=dest) from exc
    _remove_stale(dest)


def check_writable(path: str | Path) -> None:
    """Fail early when ``path`` cannot be written (before a long computation, or before a
    command's first output when it writes several).

    Creates ``path``'s parent folders and a probe file beside it (removed at once); an
    existing ``path`` is not touched.

    Raises
    ------
    InputError
        The destination is a folder, its folder cannot be created, or no file can be
        created in it.
    """
    dest = Path(path)
    _prepare_parent(dest)
    _remove_quietly(_create_temp(dest, ".probe"))


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file, fsync, rename).

    Raises
    ------
    InputError
        If the destination cannot be written.
    """
    dest = Path(path)
    with atomic_path(dest) as tmp:
        try:
            with open(tmp, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:
            raise InputError(f"cannot write ({exc.strerror or exc})", path=dest) from exc


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8, ``\\n`` line endings) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()
    except OSError:
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
