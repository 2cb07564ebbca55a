"""The pattern every typed artifact follows: one class per kind with load, save, validate
and summary.

:class:`Artifact` is the protocol-like base: ``load(path) -> cls`` reads and validates a
file (every problem an :class:`~acs_cli.errors.InputError` naming the file and the key),
``save(path)`` writes the same format atomically, ``validate()`` checks the in-memory
object (shapes, finiteness) and ``summary()`` gives a few lines for a person.

:class:`YamlArtifact` implements ``load`` and ``save`` for the YAML artifacts
(``intrinsics.yaml``, ``joint.yaml``, ``relpose.yaml``, ...): a subclass sets
:attr:`~Artifact.KIND`, holds the header (:func:`acs_cli.io.artifacts.make_header`) in a
``header`` field, and writes two methods, ``body()`` (the keys after the header, in file
order) and the classmethod ``from_doc(doc, path)`` (the typed object from the parsed
file). The NPZ poses artifact (:class:`acs_cli.io.poses.PosesArtifact`) subclasses
:class:`Artifact` directly.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar, TypeVar

from acs_cli.io.artifacts import check_yaml_artifact, load_yaml_file, write_yaml_artifact

__all__ = ["HEADER_KEYS", "Artifact", "Section", "YamlArtifact", "header_of"]

A = TypeVar("A", bound="Artifact")
Y = TypeVar("Y", bound="YamlArtifact")

#: The keys :func:`acs_cli.io.artifacts.make_header` writes, in order.
HEADER_KEYS = ("schema", "schema_version", "tool", "created", "inputs", "method", "units", "frames")


def header_of(doc: dict[str, Any]) -> dict[str, Any]:
    """The header keys of a parsed artifact (those of :data:`HEADER_KEYS` it has)."""
    return {k: doc[k] for k in HEADER_KEYS if k in doc}


class Section:
    """An artifact's section (a dataclass) whose keys are its fields, in their order."""

    def to_plain(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}  # type: ignore[arg-type]


class Artifact(ABC):
    """One artifact kind: typed fields, ``load``, ``save``, ``validate``, ``summary``.

    Subclasses are (frozen) dataclasses; ``header`` is the artifact header
    (:func:`acs_cli.io.artifacts.make_header`, possibly with kind-specific keys) and
    ``source`` the file it was loaded from (``None`` for one made in memory).
    """

    #: The kind: the schema is ``"acscal/<KIND>"``.
    KIND: ClassVar[str]

    header: dict[str, Any]
    source: str | None

    @classmethod
    @abstractmethod
    def load(cls: type[A], path: str | Path) -> A:
        """Read and validate an artifact file.

        Raises
        ------
        InputError
            An unreadable file, another kind, a newer schema, or a key that is missing or
            malformed (the message names the file and the key).
        """

    @abstractmethod
    def save(self, path: str | Path) -> None:
        """Write the artifact atomically, in the file format :meth:`load` reads."""

    @abstractmethod
    def summary(self) -> str:
        """A few lines for a person: the estimates with their standard deviations."""

    def validate(self) -> None:  # noqa: B027 - optional hook, a no-op by default
        """Check the in-memory fields (shapes, finiteness); raise ``InputError`` naming
        :attr:`source`. :meth:`load` calls it; :meth:`save` calls it before writing."""

    @property
    def units(self) -> dict[str, Any]:
        """The header's ``units`` (``{}`` when absent)."""
        units = self.header.get("units")
        return units if isinstance(units, dict) else {}

    @property
    def inputs(self) -> dict[str, Any]:
        """The header's ``inputs`` (``{role: {path, sha256}}``; ``{}`` when absent)."""
        inputs = self.header.get("inputs")
        return inputs if isinstance(inputs, dict) else {}


class YamlArtifact(Artifact):
    """A YAML artifact: the header of :func:`~acs_cli.io.artifacts.make_header`, then a body.

    Subclasses implement :meth:`body` and :meth:`from_doc`; :meth:`load` and :meth:`save`
    are done here (kind and version checks in
    :func:`~acs_cli.io.artifacts.check_yaml_artifact`, atomic writes in
    :func:`~acs_cli.io.artifacts.write_yaml_artifact`).
    """

    #: Dotted keys :meth:`load` requires before :meth:`from_doc` runs.
    REQUIRED: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def body(self) -> dict[str, Any]:
        """The keys after the header, in the order they are written."""

    @classmethod
    @abstractmethod
    def from_doc(cls: type[Y], doc: dict[str, Any], path: Path) -> Y:
        """The typed artifact from a parsed file (header and body), validated."""

    @classmethod
    def load(cls: type[Y], path: str | Path) -> Y:
        """Read, check the kind and version, parse and validate (see :class:`Artifact`)."""
        p = Path(path)
        return cls.from_parsed(load_yaml_file(p, "a YAML artifact"), p)

    @classmethod
    def from_parsed(cls: type[Y], doc: Any, path: str | Path) -> Y:
        """:meth:`load` on a file already parsed (``load_yaml_file``): the same checks."""
        p = Path(path)
        art = cls.from_doc(check_yaml_artifact(doc, p, cls.KIND, cls.REQUIRED), p)
        art.validate()
        return art

    def save(self, path: str | Path) -> None:
        """Validate, then write header and body atomically."""
        self.validate()
        write_yaml_artifact(path, self.header, self.body())

    def to_doc(self) -> dict[str, Any]:
        """Header and body as one mapping (what the file holds, before YAML conversion)."""
        return {**self.header, **self.body()}
