"""YAML artifacts: a header (schema, tool, inputs with SHA-256, method, units, frames) + a body.

Every artifact starts with the keys :func:`make_header` returns; the stage's results follow.
:func:`read_yaml_artifact` checks that an artifact is the expected kind, not from a newer
acscal, and holds the keys a stage needs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from collections.abc import Iterable, Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import yaml

import acs_cli
from acs_cli.errors import InputError
from acs_cli.io.atomic import MAX_YAML_BYTES, atomic_write_text, content_sha256, read_input_bytes
from acs_cli.io.validate import short_repr

__all__ = [
    "SCHEMA_VERSION",
    "ReadInput",
    "check_yaml_artifact",
    "get_path",
    "load_yaml_file",
    "make_header",
    "read_yaml_artifact",
    "sha256_of",
    "to_plain",
    "write_yaml_artifact",
]

#: Version of the artifact schemas this acscal writes (and the newest it reads).
SCHEMA_VERSION = 1

_MISSING: Any = object()


def sha256_of(path: str | Path, *, exclude: Iterable[str | Path] = ()) -> str:
    """SHA-256 (hex) of a file's content, or of a folder's files.

    For a folder, the hash covers every regular file below it (symlinked folders are not
    followed) in sorted order of relative POSIX path: each contributes its path, a NUL and
    the SHA-256 of its content.

    Parameters
    ----------
    path : str or Path
        The file or folder.
    exclude : iterable of str or Path
        Folders below ``path`` left out of a folder's hash (a run's output folder inside
        its own image folder: its outputs must not change its inputs' fingerprint).

    Raises
    ------
    InputError
        If the path does not exist or cannot be read.
    """
    p = Path(path)
    skip = {os.path.realpath(e) for e in exclude}
    try:
        if p.is_dir():
            files: list[tuple[str, Path]] = []
            for root, dirs, names in os.walk(p):
                dirs[:] = sorted(d for d in dirs if os.path.realpath(Path(root) / d) not in skip)
                for name in names:
                    f = Path(root) / name
                    if f.is_file():
                        files.append((f.relative_to(p).as_posix(), f))
            h = hashlib.sha256()
            for rel, f in sorted(files):
                h.update(rel.encode("utf-8", "surrogateescape") + b"\0" + content_sha256(f))
            return h.hexdigest()
        return content_sha256(p).hex()
    except FileNotFoundError as exc:
        raise InputError("no such file", path=p) from exc
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or exc})", path=p) from exc


class ReadInput(Protocol):
    """An input read already (:class:`acs_cli.io.poses.PosesArtifact`): its file and the
    SHA-256 of the bytes read."""

    @property
    def source(self) -> str | None: ...

    @property
    def sha256(self) -> str | None: ...


def make_header(
    kind: str,
    inputs: Mapping[str, str | Path | ReadInput],
    method: str,
    units: Mapping[str, Any],
    frames: Mapping[str, Any],
) -> dict[str, Any]:
    """The header every artifact starts with.

    Parameters
    ----------
    kind : str
        The artifact's kind, e.g. ``"joint"``; the schema is ``"acscal/<kind>"``.
    inputs : mapping of str to path or ReadInput
        The files (or folders) the artifact derives from, by role (``"traj_a"``, ...);
        each is recorded with its path and SHA-256 (of the bytes already read, for an
        input read so, as :class:`~acs_cli.io.poses.PosesArtifact`).
    method : str
        The estimator and its options, in words.
    units : mapping
        The unit of each quantity, e.g. ``{"length": "A units", "angles": "deg"}``.
    frames : mapping
        The frames the quantities are expressed in.

    Returns
    -------
    dict
        ``schema``, ``schema_version``, ``tool`` (name, version), ``created`` (UTC ISO
        8601), ``inputs`` (``{name: {path, sha256}}``), ``method``, ``units``, ``frames``.

    Raises
    ------
    InputError
        If an input cannot be read.
    """
    return {
        "schema": f"acscal/{kind}",
        "schema_version": SCHEMA_VERSION,
        "tool": {"name": "acscal", "version": acs_cli.__version__},
        "created": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "inputs": {
            str(name): {"path": str(p), "sha256": sha256_of(p)}
            if isinstance(p, (str, Path))
            else {"path": str(p.source), "sha256": p.sha256 or sha256_of(str(p.source))}
            for name, p in inputs.items()
        },
        "method": method,
        "units": to_plain(dict(units)),
        "frames": to_plain(dict(frames)),
    }


def to_plain(obj: Any) -> Any:
    """Recursively convert to YAML/JSON-safe Python: dicts, lists, str, int, float, bool, None.

    numpy arrays become (nested) lists, numpy scalars Python scalars, tuples lists, paths
    strings, dataclasses dicts; mapping keys become strings.

    Raises
    ------
    TypeError
        For any other object type (a programming error).
    """
    if isinstance(obj, np.ndarray):
        return to_plain(obj.tolist())
    if isinstance(obj, np.generic):  # before the builtins: np.float64 subclasses float
        return str(obj) if isinstance(obj, (np.str_, np.bytes_)) else to_plain(obj.item())
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    if isinstance(obj, Mapping):
        return {str(k): to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_plain(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_plain({f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)})
    raise TypeError(f"cannot store a {type(obj).__name__} in an artifact")


def write_yaml_artifact(
    path: str | Path, header: Mapping[str, Any], body: Mapping[str, Any]
) -> None:
    """Write ``header`` then ``body`` as one YAML mapping, atomically.

    Parameters
    ----------
    path : str or Path
        Destination file.
    header : mapping
        From :func:`make_header`.
    body : mapping
        The results; numpy arrays and scalars are converted with :func:`to_plain`. Lists of
        numbers are written in flow style (a 4x4 matrix is four ``[a, b, c, d]`` rows).

    Raises
    ------
    ValueError
        If a body key repeats a header key (a programming error).
    InputError
        If the destination cannot be written.
    """
    clash = sorted(set(header) & set(body))
    if clash:
        raise ValueError(f"body keys {clash} clash with the artifact header")
    doc = to_plain({**header, **body})
    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, allow_unicode=True)
    atomic_write_text(path, text)


def get_path(
    d: Mapping[str, Any], key: str, default: Any = _MISSING, *, source: str | Path | None = None
) -> Any:
    """The value at a dotted key such as ``"joint.position_in_a"``.

    Parameters
    ----------
    d : mapping
        A nested mapping (an artifact).
    key : str
        Dot-separated path of mapping keys.
    default : optional
        Returned when the key is missing; without it a missing key raises.
    source : str or Path, optional
        The artifact's file, named in the error.

    Raises
    ------
    InputError
        If the key is missing and no ``default`` is given.
    """
    node: Any = d
    for part in key.split("."):
        if isinstance(node, Mapping) and part in node:
            node = node[part]
        else:
            if default is not _MISSING:
                return default
            raise InputError(f"missing key '{key}'", path=source)
    return node


#: Most values aliases may add to a YAML document (its size with every alias expanded,
#: less its own nodes): a few merged defaults pass, an alias bomb ("billion laughs") not.
YAML_ALIAS_BUDGET = 10_000


def _expanded_size(node: yaml.Node, memo: dict[int, int]) -> int:
    """Nodes of ``node``'s tree with every alias expanded (shared nodes counted per use)."""
    done = memo.get(id(node))
    if done is not None:
        return done
    memo[id(node)] = 1  # a recursive alias (a node inside itself) counts once
    size = 1
    if isinstance(node, yaml.SequenceNode):
        size += sum(_expanded_size(child, memo) for child in node.value)
    elif isinstance(node, yaml.MappingNode):
        size += sum(_expanded_size(k, memo) + _expanded_size(v, memo) for k, v in node.value)
    memo[id(node)] = size
    return size


def _distinct_nodes(node: yaml.Node, seen: set[int]) -> bool:
    """Add the ids of ``node``'s distinct nodes to ``seen``; whether one is reached twice
    (an alias: the composer shares the anchored node)."""
    shared = False
    stack = [node]
    while stack:
        n = stack.pop()
        if id(n) in seen:
            shared = True
            continue
        seen.add(id(n))
        if isinstance(n, yaml.SequenceNode):
            stack.extend(n.value)
        elif isinstance(n, yaml.MappingNode):
            stack.extend(x for pair in n.value for x in pair)
    return shared


#: libyaml's scanner and parser where PyYAML was built with it (the wheels are): the same
#: events and marks as the pure-Python ones, several times faster. The nodes are composed in
#: Python (:class:`_StrictLoader`): libyaml's composer recurses in C without a limit, and a
#: 200 kB document nested 100,000 deep crashed the process (Python's raises RecursionError).
_SafeLoader: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _StrictLoader(yaml.composer.Composer, _SafeLoader):  # type: ignore[valid-type,misc]
    """A safe loader that refuses a key repeated in one mapping (YAML forbids it; PyYAML
    would silently keep the last value) and aliases that expand the document by more than
    :data:`YAML_ALIAS_BUDGET` values (an alias bomb: a few kilobytes that every walk over the
    data, or a message quoting it, sees as gigabytes)."""

    def __init__(self, stream: Any) -> None:
        _SafeLoader.__init__(self, stream)
        yaml.composer.Composer.__init__(self)

    def get_single_node(self) -> Any:
        node = super().get_single_node()
        seen: set[int] = set()
        if node is not None and _distinct_nodes(node, seen):
            extra = _expanded_size(node, {}) - len(seen)
            if extra > YAML_ALIAS_BUDGET:
                raise yaml.composer.ComposerError(
                    None,
                    None,
                    f"aliases (*name) expand the document by {extra} values, more than the "
                    f"{YAML_ALIAS_BUDGET} allowed (an alias bomb?)",
                    node.start_mark,
                )
        return node


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        try:
            first = seen.get(key)
        except TypeError:  # an unhashable key: the constructor below says so
            continue
        if first is not None:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"duplicate key {short_repr(key)} (first on line {first + 1})",
                key_node.start_mark,
            )
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=True)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def load_yaml_file(path: str | Path, what: str = "a YAML file") -> Any:
    """Parse a YAML file; every failure is an :class:`InputError` naming the file (and line).

    Parameters
    ----------
    path : str or Path
    what : str
        What the file should be, for the message when it is a folder.
    """
    p = Path(path)
    data = read_input_bytes(p, what, MAX_YAML_BYTES)
    try:
        return yaml.load(data, Loader=_StrictLoader)  # a SafeLoader: no arbitrary objects
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = None if mark is None else mark.line + 1
        problem = exc.problem or exc.context or "syntax error"
        raise InputError(f"not valid YAML: {problem}", path=p, line=line) from exc
    except Exception as exc:  # bad encodings, deep nesting, ...: all mean "not YAML"
        raise InputError(f"not valid YAML ({type(exc).__name__})", path=p) from exc


def read_yaml_artifact(path: str | Path, kind: str, required: Sequence[str] = ()) -> dict[str, Any]:
    """Read an acscal YAML artifact and check its kind, version and keys.

    Parameters
    ----------
    path : str or Path
        The artifact file.
    kind : str
        The expected kind: the schema must be ``"acscal/<kind>"``.
    required : sequence of str
        Dotted keys that must be present, e.g. ``["joint.position_in_a"]``.

    Returns
    -------
    dict
        The whole artifact (header and body).

    Raises
    ------
    InputError
        Missing or unreadable file, not YAML, not a mapping, no schema, another stage's
        artifact, a newer schema_version, or a missing required key.
    """
    p = Path(path)
    return check_yaml_artifact(load_yaml_file(p, "a YAML artifact"), p, kind, required)


def check_yaml_artifact(
    doc: Any, path: str | Path, kind: str, required: Sequence[str] = ()
) -> dict[str, Any]:
    """The checks of :func:`read_yaml_artifact` on a document already parsed from ``path``
    (kind, version, required keys): read a file once, then decide what it is."""
    p = Path(path)
    expected = f"acscal/{kind}"
    if not isinstance(doc, dict):
        raise InputError(
            f"not an acscal artifact: expected a YAML mapping, got {type(doc).__name__}", path=p
        )
    schema = doc.get("schema")
    if schema is None:
        raise InputError(f"not an acscal artifact (no 'schema' key), expected {expected}", path=p)
    if schema != expected:
        raise InputError(
            f"this is a {schema} artifact, expected {expected}: an artifact from another stage?",
            path=p,
        )
    version = doc.get("schema_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise InputError(f"'schema_version' must be an integer, got {short_repr(version)}", path=p)
    if version > SCHEMA_VERSION:
        raise InputError(
            f"schema_version {version} was written by a newer acscal (this one reads up to "
            f"{SCHEMA_VERSION}); upgrade acscal",
            path=p,
        )
    for key in required:
        get_path(doc, key, source=p)
    return doc
