"""The poses artifact: the NPZ ``acscal poses`` writes (``acscal/poses``), read in one go.

Arrays (see ``docs/formats.md``): ``schema``, ``schema_version``, ``T_world_cam`` (n, 4, 4),
``timestamps`` (n,), ``has_timestamps``, ``image_names`` (n,), ``header_json`` (the header
of :func:`acs_cli.io.artifacts.make_header` plus ``board``, ``intrinsics_file`` and
``timestamps_from``), ``reprojection_rms`` (n,) px, ``skipped_images`` (k,), ``corners``
(n, m, 2) px and ``board_points`` (m, 3) m. A plain NPZ with only ``T_world_cam`` (and
optionally ``timestamps``) reads too: its other fields are empty.

Poses from structure from motion (``acscal poses --sfm``) have no corners; instead they
carry ``metric_scale`` (False: translations in SfM units, an unknown scale) and the
``sfm_*`` arrays of :class:`SfmSummary` (every image and whether it was registered, the
sparse model's size and quality, the intrinsics used), and ``header_json`` has an ``sfm``
section (method, matching, options, timings).

:meth:`PosesArtifact.load` reads any camera's poses input, a poses NPZ or a trajectory of
another format, in one read of its bytes: it hashes them (:attr:`sha256`) and parses every
array from memory (:func:`acs_cli.io.trajectory.parse_npz_poses`, ``parse_npz_observations``
and ``parse_npz_quality``). The stages read each poses input so, once, and hand the artifact
down.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from acs_cli.core.intrinsics import MODELS
from acs_cli.errors import InputError
from acs_cli.io.base import Artifact
from acs_cli.io.intrinsics import check_camera
from acs_cli.io.trajectory import (
    Trajectory,
    npz_arrays_from_bytes,
    parse_npz_header,
    parse_npz_observations,
    parse_npz_poses,
    parse_npz_quality,
    parse_trajectory,
    read_input,
    write_npz_poses,
)
from acs_cli.io.validate import FloatArray

__all__ = ["SFM_KEYS", "PosesArtifact", "SfmSummary"]


#: The arrays of :class:`SfmSummary` in an ``acscal/poses`` NPZ (all present or none).
SFM_KEYS = (
    "sfm_images",
    "sfm_registered",
    "sfm_dropped_images",
    "sfm_num_models",
    "sfm_num_points3d",
    "sfm_mean_track_length",
    "sfm_reprojection_rms",
    "sfm_camera_matrix",
    "sfm_distortion",
    "sfm_intrinsics_model",
    "sfm_intrinsics_source",
    "sfm_intrinsics_refined",
    "sfm_image_size",
)
#: Where a structure-from-motion camera's intrinsics came from.
INTRINSICS_SOURCES = ("given", "self-calibrated")


@dataclass(frozen=True, eq=False)
class SfmSummary:
    """What structure from motion reconstructed, as a poses NPZ records it.

    Attributes
    ----------
    images : tuple of str
        Every image of the folder, in sequence order (``sfm_images``, (N,)).
    registered : ndarray of bool, shape (N,)
        Whether each image has a pose (``sfm_registered``); the posed ones, in order, are
        the trajectory's ``image_names``.
    dropped_images : tuple of str
        Images registered only in a smaller model that was dropped (``sfm_dropped_images``).
    num_models : int
        Models the reconstruction split into (1: it did not split).
    num_points3d : int
        Sparse 3-D points of the kept model.
    mean_track_length : float
        Mean number of images observing each 3-D point.
    reprojection_rms : float
        RMS reprojection error over all observations of the kept model, pixels.
    camera_matrix : ndarray, shape (3, 3)
        ``K`` the poses were computed with, pixels (OpenCV: the centre of the top-left pixel
        at ``(0, 0)``).
    distortion : ndarray, shape (k,)
        Its distortion, OpenCV order of ``intrinsics_model``.
    intrinsics_model : {"pinhole", "rational", "fisheye"}
    intrinsics_source : {"given", "self-calibrated"}
        From an intrinsics file, or estimated by SfM from the sequence.
    intrinsics_refined : bool
        Whether SfM changed the intrinsics (self-calibrated, or refined on request).
    image_size : tuple of int
        ``(width, height)``, pixels.
    """

    images: tuple[str, ...]
    registered: np.ndarray
    dropped_images: tuple[str, ...]
    num_models: int
    num_points3d: int
    mean_track_length: float
    reprojection_rms: float
    camera_matrix: FloatArray
    distortion: FloatArray
    intrinsics_model: str
    intrinsics_source: str
    intrinsics_refined: bool
    image_size: tuple[int, int]

    @property
    def registered_names(self) -> tuple[str, ...]:
        """The images with a pose, in sequence order."""
        return tuple(n for n, r in zip(self.images, self.registered, strict=True) if r)

    @property
    def registered_fraction(self) -> float:
        """Registered images / images."""
        return float(np.mean(self.registered)) if len(self.images) else 0.0

    def validate(self, path: str | None) -> None:
        """Check shapes and values; raise :class:`InputError` naming ``path`` and the key."""
        n = len(self.images)
        reg = np.asarray(self.registered)
        if n == 0:
            raise InputError("'sfm_images' is empty", path=path)
        if reg.dtype != bool or reg.shape != (n,):
            raise InputError(f"'sfm_registered' must be {n} booleans, got {reg.shape}", path=path)
        if len(set(self.images)) != n:
            raise InputError("'sfm_images' names an image twice", path=path)
        listed = set(self.images)
        posed = set(self.registered_names)
        for name in self.dropped_images:
            if name not in listed or name in posed:
                raise InputError(
                    f"'sfm_dropped_images' holds {name!r}, which is not an unregistered image "
                    "of 'sfm_images'",
                    path=path,
                )
        if self.num_models < 1 or self.num_points3d < 0:
            raise InputError("'sfm_num_models' must be >= 1 and 'sfm_num_points3d' >= 0", path=path)
        for key, v in (
            ("sfm_mean_track_length", self.mean_track_length),
            ("sfm_reprojection_rms", self.reprojection_rms),
        ):
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"'{key}' must be a finite number >= 0, got {v}", path=path)
        if self.intrinsics_model not in MODELS:
            raise InputError(
                f"'sfm_intrinsics_model' must be one of {', '.join(MODELS)}, got "
                f"{self.intrinsics_model!r}",
                path=path,
            )
        if self.intrinsics_source not in INTRINSICS_SOURCES:
            raise InputError(
                f"'sfm_intrinsics_source' must be one of {', '.join(INTRINSICS_SOURCES)}, got "
                f"{self.intrinsics_source!r}",
                path=path,
            )
        check_camera(
            self.intrinsics_model,
            self.camera_matrix,
            self.distortion,
            self.image_size,
            path,
            prefix="sfm_",
        )

    def arrays(self) -> dict[str, np.ndarray]:
        """The ``sfm_*`` arrays to write (:data:`SFM_KEYS`)."""
        return {
            "sfm_images": np.array(list(self.images), dtype=str),
            "sfm_registered": np.asarray(self.registered, dtype=bool),
            "sfm_dropped_images": (
                np.array(list(self.dropped_images), dtype=str)
                if self.dropped_images
                else np.zeros(0, "<U1")
            ),
            "sfm_num_models": np.array(self.num_models, dtype=np.int64),
            "sfm_num_points3d": np.array(self.num_points3d, dtype=np.int64),
            "sfm_mean_track_length": np.array(self.mean_track_length, dtype=float),
            "sfm_reprojection_rms": np.array(self.reprojection_rms, dtype=float),
            "sfm_camera_matrix": np.asarray(self.camera_matrix, dtype=float),
            "sfm_distortion": np.asarray(self.distortion, dtype=float),
            "sfm_intrinsics_model": np.array(self.intrinsics_model),
            "sfm_intrinsics_source": np.array(self.intrinsics_source),
            "sfm_intrinsics_refined": np.array(bool(self.intrinsics_refined)),
            "sfm_image_size": np.array(self.image_size, dtype=np.int64),
        }

    @classmethod
    def parse(cls, arrays: Mapping[str, np.ndarray], p: Path) -> SfmSummary | None:
        """From an NPZ's arrays; ``None`` when it has no ``sfm_*`` array.

        Raises
        ------
        InputError
            Some but not all of :data:`SFM_KEYS`, or one of the wrong dtype or shape.
        """
        present = [k for k in SFM_KEYS if k in arrays]
        if not present:
            return None
        missing = [k for k in SFM_KEYS if k not in arrays]
        if missing:
            raise InputError(
                f"has structure-from-motion arrays but not {', '.join(missing)}", path=p
            )
        size = _ints(arrays, "sfm_image_size", p)
        if size.shape != (2,):
            raise InputError("'sfm_image_size' must be [width, height]", path=p)
        summary = cls(
            images=_strings(arrays, "sfm_images", p),
            registered=_bools(arrays, "sfm_registered", p),
            dropped_images=_strings(arrays, "sfm_dropped_images", p),
            num_models=int(_ints(arrays, "sfm_num_models", p, scalar=True)),
            num_points3d=int(_ints(arrays, "sfm_num_points3d", p, scalar=True)),
            mean_track_length=_float(arrays, "sfm_mean_track_length", p),
            reprojection_rms=_float(arrays, "sfm_reprojection_rms", p),
            camera_matrix=_floats(arrays, "sfm_camera_matrix", p),
            distortion=_floats(arrays, "sfm_distortion", p).reshape(-1),
            intrinsics_model=_string(arrays, "sfm_intrinsics_model", p),
            intrinsics_source=_string(arrays, "sfm_intrinsics_source", p),
            intrinsics_refined=bool(_bools(arrays, "sfm_intrinsics_refined", p, scalar=True)),
            image_size=(int(size[0]), int(size[1])),
        )
        summary.validate(str(p))
        return summary


def _decode(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _string(arrays: Mapping[str, np.ndarray], key: str, p: Path) -> str:
    a = arrays[key]
    if a.ndim != 0 or a.dtype.kind not in "US":
        raise InputError(f"'{key}' must be a string", path=p)
    return _decode(a[()])


def _strings(arrays: Mapping[str, np.ndarray], key: str, p: Path) -> tuple[str, ...]:
    a = arrays[key]
    if a.ndim != 1 or (a.size and a.dtype.kind not in "US"):
        raise InputError(f"'{key}' must be a list of strings, got {a.dtype} {a.shape}", path=p)
    return tuple(_decode(v) for v in a)


def _bools(arrays: Mapping[str, np.ndarray], key: str, p: Path, scalar: bool = False) -> Any:
    a = arrays[key]
    if a.dtype.kind != "b" or (scalar and a.ndim != 0) or (not scalar and a.ndim != 1):
        raise InputError(f"'{key}' must be {'a boolean' if scalar else 'booleans'}", path=p)
    return a[()] if scalar else np.asarray(a, dtype=bool)


def _ints(arrays: Mapping[str, np.ndarray], key: str, p: Path, scalar: bool = False) -> Any:
    a = arrays[key]
    if a.dtype.kind not in "iu" or (scalar and a.ndim != 0):
        raise InputError(f"'{key}' must be {'an integer' if scalar else 'integers'}", path=p)
    return a[()] if scalar else np.asarray(a, dtype=np.int64)


def _float(arrays: Mapping[str, np.ndarray], key: str, p: Path) -> float:
    a = arrays[key]
    if a.dtype.kind not in "iuf" or a.ndim != 0:
        raise InputError(f"'{key}' must be a number", path=p)
    return float(a)


def _floats(arrays: Mapping[str, np.ndarray], key: str, p: Path) -> FloatArray:
    a = arrays[key]
    if a.dtype.kind not in "iuf":
        raise InputError(f"'{key}' must be numeric, got dtype {a.dtype}", path=p)
    return np.asarray(a, dtype=float)


def _metric_scale(arrays: Mapping[str, np.ndarray], p: Path) -> bool | None:
    if "metric_scale" not in arrays:
        return None
    return bool(_bools(arrays, "metric_scale", p, scalar=True))


@dataclass(frozen=True, eq=False)
class PosesArtifact(Artifact):
    """A camera's poses, one per posed image (``acscal/poses`` NPZ): board poses, or the
    registered images of a structure-from-motion reconstruction; or, read from a trajectory
    of another format (TUM, KITTI, COLMAP), its poses alone.

    Attributes
    ----------
    trajectory : Trajectory
        ``T_world_cam`` (n, 4, 4) with world = the board (metres), or for SfM the first
        registered camera's frame (SfM units); timestamps (s, or image indices when
        ``has_timestamps`` is False) and image names.
    reprojection_rms : ndarray, shape (n,) or (0,)
        RMS reprojection error of each pose (PnP on the board, or the SfM observations of
        the image), pixels; empty when the file has none.
    skipped_images : tuple of str
        Images without a pose (no board, or not registered by SfM).
    corners : ndarray, shape (n, m, 2) or None
        The detected corners of each posed image (pixels, board-point order).
    board_points : ndarray, shape (m, 3) or None
        The corners in the board's frame (metres).
    metric_scale : bool or None
        False when the translations have an unknown scale (SfM units); True when metric;
        None when the file does not say (board poses, which are in metres, and plain
        NPZs).
    sfm : SfmSummary or None
        The structure-from-motion summary, for poses made by ``acscal poses --sfm``.
    header : dict
        The artifact header (``{}`` for a plain NPZ or another format).
    source : str or None
        The file (or COLMAP folder) it was read from, as given.
    sha256 : str or None
        SHA-256 of the bytes read (a COLMAP folder's ``images.txt``), when read from a
        file; artifact headers record it as the input's hash.
    """

    KIND: ClassVar[str] = "poses"

    trajectory: Trajectory
    reprojection_rms: FloatArray = field(default_factory=lambda: np.zeros(0))
    skipped_images: tuple[str, ...] = ()
    corners: FloatArray | None = None
    board_points: FloatArray | None = None
    metric_scale: bool | None = None
    sfm: SfmSummary | None = None
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
    def front_end(self) -> str:
        """``"sfm"`` (structure from motion), ``"board"`` (with corners) or ``"trajectory"``."""
        if self.sfm is not None:
            return "sfm"
        return "board" if self.corners is not None else "trajectory"

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
        if self.sfm is not None:
            self.sfm.validate(p)
            posed = self.sfm.registered_names
            if len(posed) != n:
                raise InputError(
                    f"'sfm_registered' marks {len(posed)} images registered but there are {n} "
                    "poses",
                    path=p,
                )
            names = self.trajectory.names
            if names and tuple(names) != posed:
                raise InputError(
                    "'image_names' are not the images 'sfm_registered' marks, in order", path=p
                )

    @classmethod
    def load(cls, path: str | Path, fmt: str = "auto") -> PosesArtifact:
        """Read a camera's poses input (``path`` and ``fmt`` as
        :func:`acs_cli.io.trajectory.read_trajectory` takes them) in one read of its bytes:
        a poses NPZ, every array parsed and validated, or a trajectory of another format
        (TUM, KITTI, COLMAP: ``trajectory``, ``source`` and ``sha256`` alone).

        Raises
        ------
        InputError
            A missing, truncated or corrupt file, another artifact's schema, a newer
            schema_version, or an array of the wrong shape, dtype or value; a trajectory
            reader's error.
        """
        p, data, fmt = read_input(path, fmt)
        sha256 = hashlib.sha256(data).hexdigest()
        if fmt != "npz":
            traj = parse_trajectory(p, data, fmt)
            return cls(trajectory=traj, source=str(path), sha256=sha256)
        arrays = npz_arrays_from_bytes(data, p)
        traj = parse_npz_poses(arrays, p)
        header = parse_npz_header(arrays, p)
        obs = parse_npz_observations(arrays, p)
        rms, skipped = parse_npz_quality(arrays, p)
        sfm = SfmSummary.parse(arrays, p)
        art = cls(
            trajectory=traj,
            reprojection_rms=rms,
            skipped_images=tuple(skipped),
            corners=None if obs is None else obs[0],
            board_points=None if obs is None else obs[1],
            metric_scale=_metric_scale(arrays, p),
            sfm=sfm,
            header=header,
            source=str(path),
            sha256=sha256,
        )
        art.validate()
        return art

    def save(self, path: str | Path) -> None:
        """Write the ``acscal/poses`` NPZ atomically (compressed), the keys of
        :func:`acs_cli.io.trajectory.write_npz_poses` plus ``reprojection_rms``,
        ``skipped_images``, ``corners``, ``board_points``, ``metric_scale`` and the
        ``sfm_*`` arrays when held."""
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
        if self.metric_scale is not None:
            extra["metric_scale"] = np.array(bool(self.metric_scale))
        if self.sfm is not None:
            extra.update(self.sfm.arrays())
        write_npz_poses(path, self.trajectory, extra, header=self.header or None)

    def summary(self) -> str:
        t = self.trajectory
        without = "not registered" if self.sfm is not None else "without a board"
        lines = [
            f"poses: {len(t)} posed images"
            + (f", {len(self.skipped_images)} {without}" if self.skipped_images else "")
            + ", times from "
            + str(
                self.header.get(
                    "timestamps_from", "file names" if t.has_timestamps else "image indices"
                )
            )
            + ("" if t.time_unit == "s" else " (frame numbers, not seconds)")
        ]
        rms = np.asarray(self.reprojection_rms)
        if rms.size:
            lines.append(
                f"  reprojection RMS per image: median {np.median(rms):.3g} px, max "
                f"{rms.max():.3g} px"
            )
        if self.corners is not None:
            lines.append(f"  corners: {self.corners.shape[1]} per image (bundle adjustment ready)")
        if self.sfm is not None:
            s = self.sfm
            lines.append(
                f"  structure from motion: {len(t)} of {len(s.images)} images registered "
                f"({100 * s.registered_fraction:.0f}%), {s.num_points3d} points, mean track "
                f"length {s.mean_track_length:.2f}, reprojection RMS {s.reprojection_rms:.3g} px"
            )
            lines.append(
                f"  intrinsics: {s.intrinsics_model}, {s.intrinsics_source}"
                + (", refined" if s.intrinsics_refined and s.intrinsics_source == "given" else "")
                + f"; fx {s.camera_matrix[0, 0]:.1f} fy {s.camera_matrix[1, 1]:.1f} px"
            )
            if s.num_models > 1:
                lines.append(
                    f"  the reconstruction split into {s.num_models} models: kept the largest, "
                    f"dropped {len(s.dropped_images)} image(s)"
                )
        if self.metric_scale is False:
            lines.append("  translations in SfM units: the scale is unknown")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)
