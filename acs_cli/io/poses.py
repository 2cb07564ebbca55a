"""The poses artifact: the NPZ ``acscal poses`` writes (``acscal/poses``), read in one go.

Arrays (see ``docs/formats.md``): ``schema``, ``schema_version``, ``T_world_cam`` (n, 4, 4),
``timestamps`` (n,), ``has_timestamps``, ``image_names`` (n,), ``header_json`` (the header
of :func:`acs_cli.io.artifacts.make_header` plus ``board``, ``intrinsics_file`` and
``timestamps_from``), ``reprojection_rms`` (n,) px, ``skipped_images`` (k,), ``corners``
(n, m, 2) px and ``board_points`` (m, 3) m. A plain NPZ with only ``T_world_cam`` (and
optionally ``timestamps``) reads too: its other fields are empty.

:meth:`PosesArtifact.load` opens the file once, hashes its bytes (:attr:`sha256`) and
parses every array from memory, with the checks of
:func:`acs_cli.io.trajectory.read_npz_poses`, ``read_npz_observations`` and
``read_npz_quality``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from acs_cli.errors import InputError
from acs_cli.io.base import Artifact
from acs_cli.io.trajectory import (
    BoardObservations,
    Trajectory,
    load_npz,
    parse_npz_header,
    parse_npz_observations,
    parse_npz_poses,
    parse_npz_quality,
    write_npz_poses,
)
from acs_cli.io.validate import FloatArray

__all__ = ["PosesArtifact"]


@dataclass(frozen=True, eq=False)
class PosesArtifact(Artifact):
    """A camera's board poses, one per posed image (``acscal/poses`` NPZ).

    Attributes
    ----------
    trajectory : Trajectory
        ``T_world_cam`` (n, 4, 4) with world = the board (metres), timestamps (s, or image
        indices when ``has_timestamps`` is False) and image names.
    reprojection_rms : ndarray, shape (n,) or (0,)
        RMS reprojection error of each pose's PnP, pixels; empty when the file has none.
    skipped_images : tuple of str
        Images without a board pose.
    corners : ndarray, shape (n, m, 2) or None
        The detected corners of each posed image (pixels, board-point order).
    board_points : ndarray, shape (m, 3) or None
        The corners in the board's frame (metres).
    header : dict
        The artifact header (``{}`` for a plain NPZ).
    source : str or None
        The file it was read from.
    sha256 : str or None
        SHA-256 of the file's bytes, when read from a file.
    """

    KIND: ClassVar[str] = "poses"

    trajectory: Trajectory
    reprojection_rms: FloatArray = field(default_factory=lambda: np.zeros(0))
    skipped_images: tuple[str, ...] = ()
    corners: FloatArray | None = None
    board_points: FloatArray | None = None
    header: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    sha256: str | None = None

    def __len__(self) -> int:
        return len(self.trajectory)

    @property
    def intrinsics_file(self) -> str | None:
        """The intrinsics artifact the poses were solved with, as recorded."""
        intr = self.header.get("intrinsics_file")
        return None if intr is None else str(intr)

    @property
    def observations(self) -> BoardObservations | None:
        """The corners and board points (for a bundle adjustment), or None without them."""
        if self.corners is None or self.board_points is None:
            return None
        return BoardObservations(self.corners, self.board_points, self.intrinsics_file)

    @property
    def warnings(self) -> list[str]:
        """The warnings the poses stage recorded in the header."""
        w = self.header.get("warnings")
        return [str(x) for x in w] if isinstance(w, list) else []

    def validate(self) -> None:
        p = self.source
        n = len(self.trajectory)
        rms = np.asarray(self.reprojection_rms)
        if rms.size and rms.shape != (n,):
            raise InputError(f"'reprojection_rms' must be {n} numbers, got {rms.shape}", path=p)
        if (self.corners is None) != (self.board_points is None):
            raise InputError("'corners' and 'board_points' go together", path=p)
        if self.corners is not None and self.board_points is not None:
            c, b = self.corners, self.board_points
            if c.ndim != 3 or c.shape[2] != 2 or b.shape != (c.shape[1], 3):
                raise InputError(
                    f"'corners' {c.shape} and 'board_points' {b.shape} do not match "
                    "(expected (n, m, 2) and (m, 3))",
                    path=p,
                )

    @classmethod
    def load(cls, path: str | Path) -> PosesArtifact:
        """Read a poses NPZ (one read of the file), parse and validate every array.

        Raises
        ------
        InputError
            A missing, truncated or corrupt file, another artifact's schema, a newer
            schema_version, or an array of the wrong shape, dtype or value.
        """
        p = Path(path)
        arrays, data = load_npz(p)
        traj = parse_npz_poses(arrays, p)
        header = parse_npz_header(arrays, p)
        obs = parse_npz_observations(arrays, p, header)
        rms, skipped = parse_npz_quality(arrays, p)
        art = cls(
            trajectory=traj,
            reprojection_rms=rms,
            skipped_images=tuple(skipped),
            corners=None if obs is None else obs.corners,
            board_points=None if obs is None else obs.board_points,
            header=header,
            source=str(p),
            sha256=hashlib.sha256(data).hexdigest(),
        )
        art.validate()
        return art

    def save(self, path: str | Path) -> None:
        """Write the ``acscal/poses`` NPZ atomically (compressed), the keys of
        :func:`acs_cli.io.trajectory.write_npz_poses` plus ``reprojection_rms``,
        ``skipped_images``, ``corners`` and ``board_points`` when held."""
        self.validate()
        extra: dict[str, Any] = {}
        if np.asarray(self.reprojection_rms).size:
            extra["reprojection_rms"] = np.asarray(self.reprojection_rms, dtype=float)
        extra["skipped_images"] = (
            np.array(list(self.skipped_images), dtype=str)
            if self.skipped_images
            else np.zeros(0, "<U1")
        )
        if self.corners is not None and self.board_points is not None:
            extra["corners"] = np.asarray(self.corners, dtype=float)
            extra["board_points"] = np.asarray(self.board_points, dtype=float).reshape(-1, 3)
        write_npz_poses(path, self.trajectory, extra, header=self.header or None)

    def summary(self) -> str:
        t = self.trajectory
        lines = [
            f"poses: {len(t)} posed images"
            + (f", {len(self.skipped_images)} without a board" if self.skipped_images else "")
            + (", timestamps from file names" if t.has_timestamps else ", image indices")
        ]
        rms = np.asarray(self.reprojection_rms)
        if rms.size:
            lines.append(
                f"  reprojection RMS per image: median {np.median(rms):.3g} px, max "
                f"{rms.max():.3g} px"
            )
        if self.corners is not None:
            lines.append(f"  corners: {self.corners.shape[1]} per image (bundle adjustment ready)")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)
