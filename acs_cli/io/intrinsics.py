"""The intrinsics artifact: ``intrinsics.yaml`` (``acscal/intrinsics``), one camera's
calibration.

Keys (after the header of :func:`acs_cli.io.artifacts.make_header`), as
``docs/formats.md`` lists them: ``model``, ``image_size`` ``[w, h]`` (px),
``camera_matrix`` 3x3 (px), ``distortion`` (OpenCV order, ``distortion_names``),
``rms_px``, ``per_view_rms_px`` ``{image: px}``, ``std`` (``fx fy cx cy`` px and
``distortion``, or null), ``board`` ``{cols, rows, square, units}`` (or ``target``, an
AprilGrid or ChArUco as its target YAML maps it), ``images`` ``{total,
used, skipped_no_board, dropped_outliers}``, ``detector``, ``detections_cache``,
``exports`` and ``warnings``. Only ``camera_matrix``, ``distortion`` and ``image_size`` are
required on reading (a hand-written file works); the rest takes defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from acs_cli.core.intrinsics import DISTORTION_NAMES, MODELS
from acs_cli.errors import InputError
from acs_cli.io.base import YamlArtifact, header_of
from acs_cli.io.target import target_from_mapping, target_to_mapping
from acs_cli.io.validate import (
    FloatArray,
    as_int,
    as_mapping,
    as_number,
    as_str_list,
    check_magnitude,
    optional_number,
)
from acs_cli.io.verdict import VerdictSection

__all__ = ["BoardSpec", "DroppedView", "ImagesUsed", "IntrinsicsArtifact", "check_camera"]


def check_camera(
    model: str,
    camera_matrix: Any,
    distortion: Any,
    image_size: tuple[int, int],
    path: str | Path | None,
    prefix: str = "",
) -> None:
    """Check a camera's intrinsics as an artifact holds them (keys named with ``prefix``).

    Raises
    ------
    InputError
        A camera matrix that is not 3x3 and finite with positive ``fx``, ``fy``; a
        distortion vector of another length than ``model``'s or not finite; an image size
        that is not positive.
    """
    K = np.asarray(camera_matrix, dtype=float)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(f"'{prefix}camera_matrix' must be 3x3 with positive fx, fy", path=path)
    check_magnitude(K, f"{prefix}camera_matrix", path)
    n = len(DISTORTION_NAMES[model])
    D = np.asarray(distortion, dtype=float)
    if D.shape != (n,) or not np.all(np.isfinite(D)):
        raise InputError(
            f"'{prefix}distortion' must hold {n} finite numbers for the {model} model, got "
            f"shape {D.shape}",
            path=path,
        )
    check_magnitude(D, f"{prefix}distortion", path)
    w, h = image_size
    if w <= 0 or h <= 0:
        raise InputError(f"'{prefix}image_size' must be [width, height] in pixels", path=path)


@dataclass(frozen=True)
class BoardSpec:
    """A checkerboard as an artifact records it.

    Attributes
    ----------
    cols, rows : int or None
        Inner corners along the board's x and y axes (``None``: not recorded).
    square : float or None
        Square side, metres.
    units : str
        The unit of ``square`` (``"m"``).
    """

    cols: int | None = None
    rows: int | None = None
    square: float | None = None
    units: str = "m"

    @classmethod
    def parse(cls, value: Any, key: str, path: Path | None) -> BoardSpec:
        """From an artifact's ``board`` mapping (missing entries are ``None``)."""
        d = as_mapping(value, key, path)
        cols = None if d.get("cols") is None else as_int(d["cols"], f"{key}.cols", path, minimum=2)
        rows = None if d.get("rows") is None else as_int(d["rows"], f"{key}.rows", path, minimum=2)
        square = optional_number(d.get("square"), f"{key}.square", path, positive=True)
        return cls(cols, rows, square, str(d.get("units", "m")))

    def to_plain(self) -> dict[str, Any]:
        """The ``board`` mapping."""
        return {"cols": self.cols, "rows": self.rows, "square": self.square, "units": self.units}


@dataclass(frozen=True)
class DroppedView:
    """A view the calibration dropped as an outlier: its image and first-pass RMS (px)."""

    image: str
    rms_px: float


@dataclass(frozen=True)
class ImagesUsed:
    """Which images a calibration used.

    Attributes
    ----------
    total : int or None
        Images in the folder.
    used : list of str
        Images of the final calibration.
    skipped_no_board : list of str
        Images without a detected board.
    dropped_outliers : list of DroppedView
        Views dropped as outliers.
    """

    total: int | None = None
    used: list[str] = field(default_factory=list)
    skipped_no_board: list[str] = field(default_factory=list)
    dropped_outliers: list[DroppedView] = field(default_factory=list)

    @classmethod
    def parse(cls, value: Any, key: str, path: Path | None) -> ImagesUsed:
        d = as_mapping(value, key, path)
        total = None if d.get("total") is None else as_int(d["total"], f"{key}.total", path)
        dropped: list[DroppedView] = []
        raw = d.get("dropped_outliers") or []
        if not isinstance(raw, list):
            raise InputError(f"'{key}.dropped_outliers' must be a list", path=path)
        for i, item in enumerate(raw):
            k = f"{key}.dropped_outliers[{i}]"
            m = as_mapping(item, k, path)
            dropped.append(
                DroppedView(str(m.get("image")), as_number(m.get("rms_px"), f"{k}.rms_px", path))
            )
        return cls(
            total,
            as_str_list(d.get("used"), f"{key}.used", path),
            as_str_list(d.get("skipped_no_board"), f"{key}.skipped_no_board", path),
            dropped,
        )

    def to_plain(self) -> dict[str, Any]:
        return {
            "total": self.total,
            "used": list(self.used),
            "skipped_no_board": list(self.skipped_no_board),
            "dropped_outliers": [
                {"image": d.image, "rms_px": d.rms_px} for d in self.dropped_outliers
            ],
        }


def _std(value: Any, path: Path | None) -> dict[str, Any] | None:
    """``std``: ``fx fy cx cy`` (numbers) and ``distortion`` (list of numbers), or None."""
    if value is None:
        return None
    d = as_mapping(value, "std", path)
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, list):
            out[k] = [as_number(x, f"std.{k}[{i}]", path) for i, x in enumerate(v)]
        else:
            out[k] = optional_number(v, f"std.{k}", path)
    return out


def _target(value: Any, path: Path | None) -> dict[str, Any] | None:
    """``target``: a target mapping (checked by :func:`acs_cli.io.target.target_from_mapping`)
    or None."""
    if value is None:
        return None
    return target_to_mapping(target_from_mapping(value, path, "target"))


@dataclass(frozen=True, eq=False)
class IntrinsicsArtifact(YamlArtifact):
    """One camera's intrinsic calibration (``acscal/intrinsics``).

    Attributes
    ----------
    model : {"pinhole", "rational", "fisheye"}
    image_size : tuple of int
        ``(width, height)``, pixels.
    camera_matrix : ndarray, shape (3, 3)
        ``K`` in pixels (OpenCV: the centre of the top-left pixel at ``(0, 0)``).
    distortion : ndarray, shape (k,)
        OpenCV coefficients of ``model`` (unitless), named by ``distortion_names``.
    distortion_names : list of str
    rms_px : float or None
        RMS reprojection error of the calibration, pixels.
    per_view_rms_px : dict of str to float
        RMS reprojection error of each view used, by image name, pixels.
    std : dict or None
        One-sigma ``fx fy cx cy`` (px) and ``distortion`` (list), or None.
    board : BoardSpec or None
    target : dict or None
        The AprilGrid or ChArUco target calibrated on, as a target YAML maps it
        (:func:`acs_cli.io.target.target_to_mapping`); None for a checkerboard.
    images : ImagesUsed or None
    detector : str or None
    detections_cache : str or None
        File name of the detections cache beside the artifact.
    exports : dict of str to str
        Extra files written beside it (``ros``, ``opencv``), by kind.
    warnings : list of str
    header : dict
    source : str or None
    """

    KIND: ClassVar[str] = "intrinsics"
    REQUIRED: ClassVar[tuple[str, ...]] = ("camera_matrix", "distortion", "image_size")

    model: str
    image_size: tuple[int, int]
    camera_matrix: FloatArray
    distortion: FloatArray
    distortion_names: list[str] = field(default_factory=list)
    rms_px: float | None = None
    per_view_rms_px: dict[str, float] = field(default_factory=dict)
    std: dict[str, Any] | None = None
    board: BoardSpec | None = None
    target: dict[str, Any] | None = None
    images: ImagesUsed | None = None
    detector: str | None = None
    detections_cache: str | None = None
    exports: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    header: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    verdict: VerdictSection | None = None

    def validate(self) -> None:
        p = self.source
        if self.model not in MODELS:
            raise InputError(f"unknown camera model {self.model!r}", path=p)
        check_camera(self.model, self.camera_matrix, self.distortion, self.image_size, p)

    @classmethod
    def from_doc(cls, doc: dict[str, Any], path: Path) -> IntrinsicsArtifact:
        model = str(doc.get("model", "pinhole"))
        if model not in MODELS:
            raise InputError(f"unknown camera model {model!r}", path=path)
        try:
            with np.errstate(all="ignore"):
                K = np.asarray(doc["camera_matrix"], dtype=float)
                D = np.asarray(doc["distortion"], dtype=float).ravel()
                size = np.asarray(doc["image_size"], dtype=float).ravel()
        except (TypeError, ValueError, OverflowError) as exc:
            raise InputError(
                "camera_matrix, distortion and image_size must be numbers", path=path
            ) from exc
        if (
            size.shape != (2,)
            or not np.all(np.isfinite(size))
            or np.any(size <= 0)
            or np.any(size != np.round(size))
            or np.any(size >= 2**31)
        ):
            raise InputError("'image_size' must be [width, height] in pixels", path=path)
        per_view = as_mapping(doc.get("per_view_rms_px") or {}, "per_view_rms_px", path)
        board = doc.get("board")
        images = doc.get("images")
        exports = as_mapping(doc.get("exports") or {}, "exports", path)
        art = cls(
            model=model,
            image_size=(int(size[0]), int(size[1])),
            camera_matrix=K,
            distortion=D,
            distortion_names=as_str_list(
                doc.get("distortion_names") or list(DISTORTION_NAMES[model]),
                "distortion_names",
                path,
            ),
            rms_px=optional_number(doc.get("rms_px"), "rms_px", path),
            per_view_rms_px={
                k: as_number(v, f"per_view_rms_px.{k}", path) for k, v in per_view.items()
            },
            std=_std(doc.get("std"), path),
            board=None if not isinstance(board, dict) else BoardSpec.parse(board, "board", path),
            target=_target(doc.get("target"), path),
            images=None if images is None else ImagesUsed.parse(images, "images", path),
            detector=None if doc.get("detector") is None else str(doc["detector"]),
            detections_cache=None
            if doc.get("detections_cache") is None
            else str(doc["detections_cache"]),
            exports={k: str(v) for k, v in exports.items()},
            warnings=as_str_list(doc.get("warnings"), "warnings", path),
            header=header_of(doc),
            source=str(path),
            verdict=None
            if doc.get("verdict") is None
            else VerdictSection.parse(doc["verdict"], path),
        )
        return art

    def body(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "camera_matrix": self.camera_matrix,
            "distortion": self.distortion,
            "distortion_names": list(self.distortion_names),
            "rms_px": self.rms_px,
            "per_view_rms_px": dict(self.per_view_rms_px),
            "std": self.std if self.std else None,
            "board": None if self.board is None else self.board.to_plain(),
            "target": None if self.target is None else dict(self.target),
            "images": None if self.images is None else self.images.to_plain(),
            "detector": self.detector,
            "detections_cache": self.detections_cache,
            "exports": dict(self.exports),
            **({} if self.verdict is None else {"verdict": self.verdict.to_plain()}),
            "warnings": list(self.warnings),
        }

    @property
    def principal_point(self) -> FloatArray:
        """``(cx, cy)``, pixels."""
        return np.asarray(self.camera_matrix[:2, 2], dtype=float)

    def summary(self) -> str:
        K = self.camera_matrix
        std = self.std or {}

        def pm(key: str) -> str:
            s = std.get(key)
            return "" if not isinstance(s, (int, float)) else f" +- {s:.2g}"

        w, h = self.image_size
        lines = [
            f"intrinsics: {self.model} model, {w}x{h} px"
            + ("" if self.rms_px is None else f", RMS {self.rms_px:.3g} px"),
            f"  fx {K[0, 0]:.2f}{pm('fx')}  fy {K[1, 1]:.2f}{pm('fy')}  "
            f"cx {K[0, 2]:.2f}{pm('cx')}  cy {K[1, 2]:.2f}{pm('cy')} px",
            "  distortion "
            + " ".join(
                f"{n} {v:.4g}" for n, v in zip(self.distortion_names, self.distortion, strict=False)
            ),
        ]
        if self.images is not None:
            lines.append(
                f"  views: {len(self.images.used)} used, {len(self.images.dropped_outliers)} "
                f"dropped, {len(self.images.skipped_no_board)} without a board"
            )
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)
