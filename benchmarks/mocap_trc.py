"""Real motion capture for ``bench_mocap.py``: an OpenSim TRC reader and segment poses from
rigid (Kabsch) fits of marker clusters.

Not part of acscal: the benchmark's own plumbing to turn skin-marker trajectories into the
``T_lab_segment`` tracks the rig engine takes.

Segment frames. Every segment's axes are the pelvis's anatomical axes in a reference trial
(the subject standing: ``subject02_static.trc``), built from the pelvis markers:

- ``z`` (lateral, to the right): from ``L.ASIS`` to ``R.ASIS``;
- ``x`` (anterior): from ``V.Sacral`` to the ASIS midpoint, made orthogonal to ``z``;
- ``y`` (up): ``z x x``.

The pelvis's origin is the ASIS midpoint; a thigh's or shank's origin is its cluster's
centroid in the reference trial. A segment's pose at a frame of another trial is then the
rigid motion that best maps its cluster from the reference trial to that frame (Kabsch,
least squares over the cluster's markers) applied to its reference pose. Standing, every
segment's axes are the pelvis's: ``x`` forward, ``y`` up, ``z`` to the subject's right, so
the left side mirrors onto the right by ``z -> -z``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

FloatArray = np.ndarray

#: Marker clusters, one rigid body each (the data's README); ``{s}`` is ``R`` or ``L``.
CLUSTERS = {
    "pelvis": ("R.ASIS", "L.ASIS", "V.Sacral"),
    "thigh": ("{s}.Thigh.Upper", "{s}.Thigh.Front", "{s}.Thigh.Rear"),
    "shank": ("{s}.Shank.Upper", "{s}.Shank.Front", "{s}.Shank.Rear"),
}


@dataclass(frozen=True)
class Trc:
    """A TRC file: ``markers[name]`` ``(n, 3)`` in metres (NaN where missing), times (s)."""

    times: FloatArray
    rate: float
    markers: dict[str, FloatArray]


def read_trc(path: Path) -> Trc:
    """Read an OpenSim TRC file (tab-separated; marker names on line 4, data from line 6).

    Blank cells become NaN; lengths are converted to metres from the header's ``Units``.
    """
    lines = path.read_text().splitlines()
    head = dict(zip(lines[1].split("\t"), lines[2].split("\t"), strict=False))
    unit = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}[head["Units"].strip()]
    names = [c.strip() for c in lines[3].split("\t")[2:] if c.strip()]
    rows = []
    for line in lines[5:]:
        cells = line.split("\t")
        if not line.strip() or not cells[0].strip():
            continue
        cells += [""] * (2 + 3 * len(names) - len(cells))
        rows.append([float(c) if c.strip() else np.nan for c in cells[: 2 + 3 * len(names)]])
    data = np.asarray(rows, float)
    xyz = data[:, 2:].reshape(data.shape[0], len(names), 3) * unit
    return Trc(data[:, 1], float(head["DataRate"]), {m: xyz[:, i] for i, m in enumerate(names)})


def kabsch(P: FloatArray, Q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The rigid motions ``(R, t)`` with ``Q_i ~ R_i P + t_i``, per frame.

    ``P`` ``(m, 3)``: the cluster's reference shape; ``Q`` ``(n, m, 3)``: the markers per
    frame. Returns ``R`` ``(n, 3, 3)``, ``t`` ``(n, 3)`` and the fit's RMS residual ``(n,)``.
    """
    p0 = P.mean(axis=0)
    q0 = Q.mean(axis=1)
    H = np.einsum("mi,nmj->nij", P - p0, Q - q0[:, None, :])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    D = np.zeros((Q.shape[0], 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)
    t = q0 - np.einsum("nij,j->ni", R, p0)
    fit = np.einsum("nij,mj->nmi", R, P) + t[:, None, :]
    rms = np.sqrt(np.mean(np.sum((fit - Q) ** 2, axis=2), axis=1))
    return R, t, rms


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v))


def pelvis_axes(ref: dict[str, FloatArray]) -> FloatArray:
    """The pelvis's anatomical axes ``(3, 3)`` (columns x forward, y up, z right) in the
    lab, from the reference positions ``(3,)`` of its markers."""
    mid = 0.5 * (ref["R.ASIS"] + ref["L.ASIS"])
    z = _unit(ref["R.ASIS"] - ref["L.ASIS"])
    x = mid - ref["V.Sacral"]
    x = _unit(x - (x @ z) * z)
    return np.stack([x, np.cross(z, x), z], axis=1)


def reference_positions(trc: Trc) -> dict[str, FloatArray]:
    """Each marker's mean position ``(3,)`` over the frames where it is seen."""
    return {m: np.nanmean(xyz, axis=0) for m, xyz in trc.markers.items()}


def segment_markers(segment: str, side: str) -> tuple[str, ...]:
    """The markers of ``segment`` (``pelvis``, ``thigh``, ``shank``) on ``side`` (R, L)."""
    return tuple(m.format(s=side) for m in CLUSTERS[segment])


@dataclass(frozen=True)
class SegmentTrack:
    """``T_lab_segment`` ``(n, 4, 4)`` (metres), the Kabsch fit's RMS residual ``(n,)`` (m)
    and the segment's pose in the reference trial ``(4, 4)``."""

    T_lab_seg: FloatArray
    fit_rms: FloatArray
    T_lab_seg_ref: FloatArray


def segment_track(trc: Trc, ref: dict[str, FloatArray], segment: str, side: str) -> SegmentTrack:
    """A segment's poses over ``trc`` (see the module's docstring for its frame)."""
    names = segment_markers(segment, side)
    P = np.stack([ref[m] for m in names])
    Q = np.stack([trc.markers[m] for m in names], axis=1)
    if np.isnan(Q).any():
        raise ValueError(f"{segment} ({side}): missing markers; fill or drop those frames")
    R, t, rms = kabsch(P, Q)
    T0 = np.eye(4)
    T0[:3, :3] = pelvis_axes(ref)
    T0[:3, 3] = 0.5 * (ref["R.ASIS"] + ref["L.ASIS"]) if segment == "pelvis" else P.mean(axis=0)
    M = np.broadcast_to(np.eye(4), (R.shape[0], 4, 4)).copy()
    M[:, :3, :3], M[:, :3, 3] = R, t
    return SegmentTrack(np.asarray(M @ T0), rms, T0)


def in_segment(T_lab_seg: FloatArray, p_lab: FloatArray) -> FloatArray:
    """A lab point ``(3,)`` in a segment's frame, given the segment's pose ``(4, 4)``."""
    return np.asarray(T_lab_seg[:3, :3].T @ (p_lab - T_lab_seg[:3, 3]))
