"""The ``verdict`` section an artifact carries: how well its data determined it.

``level`` is ``good``, ``weak`` (past a warning level) or ``refused`` (past a refusal
level, written only with ``--accept-weak``); ``accepted_weak`` says the override was used;
``measures`` maps each measure (``joint_std_fraction (the joint in A)``, ...) to its
``value``, its ``warn`` and ``refuse`` levels and its ``level``. The policy is
:mod:`acs_cli.core.quality`; ``docs/degeneracy.md`` documents it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from acs_cli.core.quality import LEVELS, Verdict
from acs_cli.errors import InputError
from acs_cli.io.validate import as_bool, as_mapping, optional_number

Source = Path | str | None


@dataclass(frozen=True)
class MeasureRecord:
    """One measure as written: its value (None: not determined), levels and verdict."""

    value: float | None
    warn: float
    refuse: float
    level: str
    subject: str = ""


@dataclass(frozen=True)
class VerdictSection:
    """An artifact's ``verdict``.

    Attributes
    ----------
    level : {"good", "weak", "refused"}
    accepted_weak : bool
    measures : dict of str to MeasureRecord
    """

    level: str = "good"
    accepted_weak: bool = False
    measures: dict[str, MeasureRecord] = field(default_factory=dict)

    @property
    def weak(self) -> bool:
        """Past a warning level: files exported from the artifact are marked."""
        return self.level != "good"

    @classmethod
    def from_verdict(cls, v: Verdict) -> VerdictSection:
        return cls.parse(v.to_plain(), None)

    @classmethod
    def parse(cls, value: Any, path: Source) -> VerdictSection:
        d = as_mapping(value, "verdict", path)
        level = str(d.get("level", "good"))
        if level not in LEVELS:
            raise InputError(
                f"'verdict.level' must be one of {', '.join(LEVELS)}, got {level[:40]!r}",
                path=path,
            )
        measures = {}
        for key, raw in as_mapping(d.get("measures") or {}, "verdict.measures", path).items():
            m = as_mapping(raw, f"verdict.measures.{key}", path)
            mlevel = str(m.get("level", "good"))
            if mlevel not in LEVELS:
                raise InputError(f"'verdict.measures.{key}.level' is not a level", path=path)
            measures[str(key)] = MeasureRecord(
                value=optional_number(m.get("value"), f"verdict.measures.{key}.value", path),
                warn=_number(m.get("warn"), f"verdict.measures.{key}.warn", path),
                refuse=_number(m.get("refuse"), f"verdict.measures.{key}.refuse", path),
                level=mlevel,
                subject=str(m.get("subject", "")),
            )
        accepted = as_bool(d.get("accepted_weak", False), "verdict.accepted_weak", path)
        return cls(level, accepted, measures)

    def to_plain(self) -> dict[str, Any]:
        return {
            "level": self.level,
            "accepted_weak": self.accepted_weak,
            "measures": {
                k: {
                    "subject": m.subject,
                    "value": m.value,
                    "warn": m.warn,
                    "refuse": m.refuse,
                    "level": m.level,
                }
                for k, m in self.measures.items()
            },
        }


def _number(value: Any, key: str, path: Source) -> float:
    out = optional_number(value, key, path)
    if out is None:
        raise InputError(f"missing key {key!r}", path=path)
    return out


def weak_marks(artifact: str, verdict: VerdictSection | None) -> list[str]:
    """Comment lines that mark a file exported from a weak result (none when good)."""
    if verdict is None or not verdict.weak:
        return []
    how = (
        "was refused and written only with --accept-weak"
        if verdict.accepted_weak and verdict.level == "refused"
        else f"is {verdict.level}"
    )
    return [f"WEAK RESULT: {artifact} {how} (see its verdict section); check before use"]
