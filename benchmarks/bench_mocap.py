"""Motion capture with the rig engine (issue 19): shared worlds and recordings, simulated and
real.

Four parts, each printing Markdown tables to stdout (progress on stderr):

1. Simulated hip trial (:func:`sample_data_gen.mocap_sim.hip_trial`: pelvis and femur in one
   lab world, independent pose noise per frame, a pelvis that hardly turns), over ``--seeds``
   seeds: the hip centre in the pelvis from the rig with ``world: shared``
   (``Recordings.single(n, True)``), from the two-camera overlap (Algorithm I,
   :func:`estimate_joint_overlap`) and from the rig with a world per body (the old
   behaviour). Error against the truth, reported std, and whether the one covers the other.
2. The two-recording chain (hip trial + knee trial, ``Recordings`` of two names, both
   shared) against each joint calibrated alone on its own trial: hip centre, knee axis and
   knee point.
3. Parts 1 and 2 again with a skin-marker-like error on the moving segment (``--slide-mm``:
   correlated over time and with the joint angle); no target, reported as found.
4. Real data (``--data``, OpenSim's Hamner running trial, see its README.md): pelvis, thighs
   and shanks from Kabsch fits of marker clusters (:mod:`benchmarks.mocap_trc`); the rig
   ``pelvis -ball- thigh -hinge- shank`` on each leg, one recording, one shared world, on
   the whole trial, on each half and on ``--blocks`` consecutive blocks. No ground truth:
   consistency between halves and blocks, left against right, and the knee against the
   static trial's epicondyle markers.

    .venv/bin/python benchmarks/bench_mocap.py                   # all (~1-2 min here)
    .venv/bin/python benchmarks/bench_mocap.py --seeds 100       # more seeds
    .venv/bin/python benchmarks/bench_mocap.py --skip-sim        # real data only (~10 s)

Lengths in millimetres, angles in degrees. A std is the root of the covariance's trace for a
point (3-D, comparable with the error's norm) and ``axis_std_deg_in`` (the same for the unit
vector) for an axis.
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

# as the acscal command does (acs_cli/cli/__init__.py): one BLAS thread unless told otherwise
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import datetime as dt
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from scipy.stats import chi2

from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.rig import rig_topology
from acs_cli.core.rig_solve import CameraTrack, Recordings, RigEstimate, estimate_rig
from acs_cli.errors import AcsError

sys.path.insert(0, str(Path(__file__).resolve().parent))  # its helper, when imported
import mocap_trc as trc
from bench_rig import load, log, machine_info

from sample_data_gen import mocap_sim as M

HIP = rig_topology(["pelvis", "femur"], [("hip", ["pelvis", "femur"], "ball")], "pelvis")
KNEE = rig_topology(["femur", "tibia"], [("knee", ["femur", "tibia"], "hinge")], "femur")
LEG = rig_topology(
    ["pelvis", "femur", "tibia"],
    [("hip", ["pelvis", "femur"], "ball"), ("knee", ["femur", "tibia"], "hinge")],
    "pelvis",
)
REAL_LEG = rig_topology(
    ["pelvis", "thigh", "shank"],
    [("hip", ["pelvis", "thigh"], "ball"), ("knee", ["thigh", "shank"], "hinge")],
    "pelvis",
)
DATA = Path("/work/shared/data/opensim_running")
#: The truth's knee point: the axis point nearest the femur's origin (the rig's convention).
_U = M.KNEE_AXIS_IN_FEMUR
KNEE_POINT_IN_FEMUR = M.KNEE_IN_FEMUR - (M.KNEE_IN_FEMUR @ _U) * _U
CHI2_95_3D = float(chi2.ppf(0.95, 3))
T = TypeVar("T")


def table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(v)))) if np.size(v) else float("nan")


def std3(C: np.ndarray) -> float:
    """The 3-D std of a point: root of the covariance's trace."""
    return float(np.sqrt(max(np.trace(C), 0.0)))


def axis_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two axes, either sign (degrees)."""
    c = abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(min(1.0, c))))


def ratio_interval(base: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> str:
    """RMS(new) / RMS(base) over seeds and its 90% paired-bootstrap interval."""
    if base.size == 0 or base.size != new.size:
        return "—"
    idx = rng.integers(0, base.size, size=(2000, base.size))
    r = np.sqrt(np.mean(new[idx] ** 2, axis=1) / np.mean(base[idx] ** 2, axis=1))
    lo, hi = np.quantile(r, [0.05, 0.95])
    return f"{rms(new) / rms(base):.3f} ({lo:.3f}-{hi:.3f})"


# --------------------------------------------------------------------------- simulation


@dataclass
class Stat:
    """One estimator's results for one quantity over seeds."""

    err: list[float] = field(default_factory=list)  # error norm (mm or deg)
    std: list[float] = field(default_factory=list)  # reported std, same unit
    vec: list[np.ndarray] = field(default_factory=list)  # error vectors (points, mm)
    nees: list[float] = field(default_factory=list)  # e' C^-1 e (points)
    refused: list[str] = field(default_factory=list)

    def add_point(self, est: np.ndarray, C: np.ndarray, truth: np.ndarray) -> None:
        e = 1000.0 * (est - truth)
        self.err.append(float(np.linalg.norm(e)))
        self.std.append(1000.0 * std3(C))
        self.vec.append(e)
        self.nees.append(float(e @ np.linalg.pinv(1e6 * C, rcond=1e-10) @ e))

    def add_axis(self, est: np.ndarray, std_deg: float, truth: np.ndarray) -> None:
        self.err.append(axis_angle_deg(est, truth))
        self.std.append(std_deg)


def tracks_of(*trials: dict[str, np.ndarray]) -> dict[str, CameraTrack]:
    """Trials one after the other on one timeline (a body is invalid where a trial does not
    see it)."""
    sizes = [next(iter(t.values())).shape[0] for t in trials]
    n = sum(sizes)
    out = {}
    for b in sorted({b for t in trials for b in t}):
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        v = np.zeros(n, bool)
        at = 0
        for t, m in zip(trials, sizes, strict=True):
            if b in t:
                T[at : at + m], v[at : at + m] = t[b], True
            at += m
        out[b] = CameraTrack(T, v)
    return out


def attempt(stat_keys: Sequence[Stat], fn: Callable[..., T], *args: Any, **kw: Any) -> T | None:
    """``fn(*args, **kw)``, or None with the refusal noted on every stat it would have fed."""
    try:
        return fn(*args, **kw)
    except AcsError as exc:
        for s in stat_keys:
            s.refused.append(str(exc))
        return None


def run_sim(
    seeds: int, frames: int, slide_mm: float, pelvis_turn_deg: float, seed0: int
) -> dict[str, Stat]:
    """Parts 1 and 2 (and 3 with ``slide_mm``): per estimator and quantity, over seeds."""
    S: dict[str, Stat] = {
        k: Stat()
        for k in (
            "hip shared",
            "hip pair",
            "hip separate",
            "chain hip",
            "chain axis",
            "chain point",
            "alone hip",
            "alone axis",
            "alone point",
        )
    }
    t0 = time.perf_counter()
    for s in range(seeds):
        rng = np.random.default_rng([seed0, s])
        hip = M.hip_trial(rng, n=frames, pelvis_turn_deg=pelvis_turn_deg, slide_mm=slide_mm)
        knee = M.knee_trial(rng, n=frames, slide_mm=slide_mm)
        n = hip.times.size
        hip_tracks = tracks_of(hip.measured)
        # 1. the hip alone: rig with a shared world (also part 2's "alone"), the pair, the
        #    rig with a world per body
        est = attempt(
            [S["hip shared"], S["alone hip"]],
            estimate_rig,
            HIP,
            hip_tracks,
            recordings=Recordings.single(n, True),
        )
        if isinstance(est, RigEstimate):
            e = est.edges["hip"]
            for key in ("hip shared", "alone hip"):
                S[key].add_point(
                    e.position_in["pelvis"], e.position_cov_in["pelvis"], M.HIP_IN_PELVIS
                )
        pair = attempt(
            [S["hip pair"]],
            estimate_joint_overlap,
            hip.measured["pelvis"],
            hip.measured["femur"],
        )
        if pair is not None:
            S["hip pair"].add_point(pair.position_in_a, pair.covariance_a, M.HIP_IN_PELVIS)
        est = attempt([S["hip separate"]], estimate_rig, HIP, hip_tracks)
        if isinstance(est, RigEstimate):
            e = est.edges["hip"]
            S["hip separate"].add_point(
                e.position_in["pelvis"], e.position_cov_in["pelvis"], M.HIP_IN_PELVIS
            )
        # 2. the chain over two recordings, and the knee alone on its trial
        m = knee.times.size
        recs = Recordings(("hip", "knee"), np.repeat([0, 1], [n, m]), (True, True))
        chain_keys = [S["chain hip"], S["chain axis"], S["chain point"]]
        est = attempt(
            chain_keys,
            estimate_rig,
            LEG,
            tracks_of(hip.measured, knee.measured),
            recordings=recs,
        )
        if isinstance(est, RigEstimate):
            e = est.edges["hip"]
            S["chain hip"].add_point(
                e.position_in["pelvis"], e.position_cov_in["pelvis"], M.HIP_IN_PELVIS
            )
            k = est.edges["knee"]
            S["chain axis"].add_axis(k.axis_in["femur"], k.axis_std_deg_in["femur"], _U)
            S["chain point"].add_point(
                k.position_in["femur"], k.position_cov_in["femur"], KNEE_POINT_IN_FEMUR
            )
        est = attempt(
            [S["alone axis"], S["alone point"]],
            estimate_rig,
            KNEE,
            tracks_of(knee.measured),
            recordings=Recordings.single(m, True),
        )
        if isinstance(est, RigEstimate):
            k = est.edges["knee"]
            S["alone axis"].add_axis(k.axis_in["femur"], k.axis_std_deg_in["femur"], _U)
            S["alone point"].add_point(
                k.position_in["femur"], k.position_cov_in["femur"], KNEE_POINT_IN_FEMUR
            )
        if (s + 1) % 10 == 0 or s + 1 == seeds:
            log(f"  {s + 1}/{seeds} seeds, {time.perf_counter() - t0:.0f} s (load {load()})")
    return S


def _cells(st: Stat, unit: str, point: bool) -> list[str]:
    if not st.err:
        return [f"{len(st.refused)}", "—", "—", "—", "—", "—"]
    err, std = np.asarray(st.err), np.asarray(st.std)
    f = "{:.2f}" if unit == "mm" else "{:.3f}"
    bias = "—"
    cover = "—"
    if point:
        V = np.asarray(st.vec)
        mean = V.mean(axis=0)
        se = V.std(axis=0, ddof=1) / np.sqrt(len(V)) if len(V) > 1 else np.full(3, np.nan)
        bias = f"{np.linalg.norm(mean):.2f} ({np.max(np.abs(mean) / se):.1f} se)"
        cover = f"{100 * np.mean(np.asarray(st.nees) < CHI2_95_3D):.0f}%"
    return [
        f"{len(st.refused)}",
        f.format(rms(err)),
        f.format(rms(std)),
        f"{rms(err) / rms(std):.2f}",
        bias,
        cover,
    ]


SIM_HEAD = [
    "estimator",
    "refused",
    "RMS error",
    "RMS std",
    "error / std",
    "mean error (largest axis / its se)",
    "95% ellipsoid covers",
]


def report_sim(S: dict[str, Stat], seeds: int) -> str:
    boot = np.random.default_rng(12345)
    out = []
    rows = [
        [label, *_cells(S[k], "mm", True)]
        for label, k in (
            ("rig, `world: shared`", "hip shared"),
            ("two-camera overlap (`estimate_joint_overlap`)", "hip pair"),
            ("rig, separate worlds (before)", "hip separate"),
        )
    ]
    out += [f"**Hip centre in the pelvis (mm), hip trial, {seeds} seeds**", ""]
    out += [table(SIM_HEAD, rows), ""]
    sh, pa = S["hip shared"], S["hip pair"]
    if len(sh.err) == len(pa.err) == seeds:
        d = np.asarray(sh.vec) - np.asarray(pa.vec)
        out += [
            "RMS(shared) / RMS(overlap), 90% paired bootstrap: "
            + ratio_interval(np.asarray(pa.err), np.asarray(sh.err), boot)
            + f"; shared minus overlap per seed: RMS {rms(np.linalg.norm(d, axis=1)):.3f} mm, "
            f"largest {np.max(np.linalg.norm(d, axis=1)):.3f} mm.",
            "",
        ]
    rows = []
    for label, k, unit in (
        ("hip centre (mm)", "hip", "mm"),
        ("knee axis in femur (deg)", "axis", "deg"),
        ("knee point in femur (mm)", "point", "mm"),
    ):
        c, a = S[f"chain {k}"], S[f"alone {k}"]
        for who, st in (("chain (2 recordings)", c), ("alone (its trial)", a)):
            rows.append([f"{label}: {who}", *_cells(st, unit, unit == "mm")])
        if len(c.err) == len(a.err) == seeds:
            rows.append(
                [
                    f"{label}: chain / alone",
                    "",
                    ratio_interval(np.asarray(a.err), np.asarray(c.err), boot),
                    "",
                    "",
                    "",
                    "",
                ]
            )
    out += [f"**Two recordings (hip trial + knee trial) against each joint alone, {seeds} seeds**"]
    out += ["", table(SIM_HEAD, rows)]
    refusals = sorted({r for st in S.values() for r in st.refused})
    if refusals:
        out += ["", "Refusals:", *(f"- {r}" for r in refusals[:5])]
    return "\n".join(out)


def run_turns(turns: Sequence[float], seeds: int, frames: int, seed0: int) -> str:
    """The hip centre against the pelvis's turn: the rig with a shared world and with a
    world per body (the noise and seeds of part 1)."""
    rows = []
    for turn in turns:
        st = {"shared": Stat(), "separate": Stat()}
        for s in range(seeds):
            rng = np.random.default_rng([seed0, s])
            hip = M.hip_trial(rng, n=frames, pelvis_turn_deg=turn)
            n = hip.times.size
            tracks = tracks_of(hip.measured)
            for key, recs in (("shared", Recordings.single(n, True)), ("separate", None)):
                est = attempt(
                    [st[key]],
                    estimate_rig,
                    HIP,
                    tracks,
                    recordings=recs,
                )
                if isinstance(est, RigEstimate):
                    e = est.edges["hip"]
                    st[key].add_point(
                        e.position_in["pelvis"], e.position_cov_in["pelvis"], M.HIP_IN_PELVIS
                    )
        for key, label in (("shared", "`world: shared`"), ("separate", "separate worlds")):
            x = st[key]
            along = (
                float(np.mean(np.asarray(x.vec), axis=0) @ M.HIP_IN_PELVIS)
                / float(np.linalg.norm(M.HIP_IN_PELVIS))
                if x.vec
                else float("nan")
            )
            rows.append([f"{turn:g}", label, *_cells(x, "mm", True), f"{along:+.2f}"])
        log(f"  pelvis turn {turn:g} deg done (load {load()})")
    return table(
        ["pelvis turn (deg)", "rig", *SIM_HEAD[1:], "mean error along the true o_p (mm)"], rows
    )


# --------------------------------------------------------------------------- real data


@dataclass
class Side:
    """One leg's solves: over spans of frames, the estimate (or the refusal)."""

    label: str
    spans: dict[str, tuple[int, int]]
    est: dict[str, RigEstimate | str]
    fit_rms: dict[str, np.ndarray]
    epicondyles: tuple[np.ndarray, np.ndarray]  # lateral, medial in the thigh (m)


def solve_side(run: trc.Trc, ref: dict[str, np.ndarray], side: str, blocks: int) -> Side:
    segs = {
        "pelvis": trc.segment_track(run, ref, "pelvis", side),
        "thigh": trc.segment_track(run, ref, "thigh", side),
        "shank": trc.segment_track(run, ref, "shank", side),
    }
    n = run.times.size
    spans = {"whole": (0, n), "first half": (0, n // 2), "second half": (n // 2, n)}
    edges = np.linspace(0, n, blocks + 1).astype(int) if blocks > 1 else np.array([], int)
    for b in range(max(blocks, 0) if blocks > 1 else 0):
        spans[f"block {b + 1}"] = (int(edges[b]), int(edges[b + 1]))
    est: dict[str, RigEstimate | str] = {}
    for name, (a, b) in spans.items():
        tracks = {s: CameraTrack(v.T_lab_seg[a:b], np.ones(b - a, bool)) for s, v in segs.items()}
        try:
            est[name] = estimate_rig(REAL_LEG, tracks, recordings=Recordings.single(b - a, True))
        except AcsError as exc:
            est[name] = str(exc)
    T0 = segs["thigh"].T_lab_seg_ref
    epi = (
        trc.in_segment(T0, ref[f"{side}.Knee.Lat"]),
        trc.in_segment(T0, ref[f"{side}.Knee.Med"]),
    )
    return Side(side, spans, est, {s: v.fit_rms for s, v in segs.items()}, epi)


def mirror(v: np.ndarray) -> np.ndarray:
    """The left side onto the right: the lateral coordinate (z) changes sign."""
    return np.asarray(v * np.array([1.0, 1.0, -1.0]))


def mirror_cov(C: np.ndarray) -> np.ndarray:
    Mi = np.diag([1.0, 1.0, -1.0])
    return np.asarray(Mi @ C @ Mi)


def _pm(v: np.ndarray, C: np.ndarray, scale: float = 1000.0, f: str = "{:.1f}") -> str:
    s = np.sqrt(np.maximum(np.diag(C), 0.0))
    return ", ".join(
        f"{f.format(scale * a)} ± {f.format(scale * b)}" for a, b in zip(v, s, strict=True)
    )


def _axis_pos(u: np.ndarray) -> np.ndarray:
    """An axis with its lateral (z) component positive (sign convention for comparisons)."""
    return u if u[2] >= 0 else -u


def line_distance(h: np.ndarray, k: np.ndarray, u: np.ndarray) -> float:
    """Distance from point ``h`` to the line through ``k`` along ``u``."""
    d = h - k
    return float(np.linalg.norm(d - (d @ u) * u))


def hip_knee_distance(est: RigEstimate) -> tuple[float, float]:
    """Distance from the hip centre to the knee axis, both in the thigh, and its std (first
    order; the two joints taken as independent, the axis's std isotropic across it)."""
    h_e, k_e = est.edges["hip"], est.edges["knee"]
    h, Ch = h_e.position_in["thigh"], h_e.position_cov_in["thigh"]
    k, Ck = k_e.position_in["thigh"], k_e.position_cov_in["thigh"]
    u = k_e.axis_in["thigh"]
    su = np.radians(k_e.axis_std_deg_in["thigh"]) / np.sqrt(2.0)
    d0 = line_distance(h, k, u)
    eps = 1e-6
    g = np.zeros(9)
    x0 = np.concatenate([h, k, u])
    for i in range(9):
        x = x0.copy()
        x[i] += eps
        uu = x[6:] / np.linalg.norm(x[6:])
        g[i] = (line_distance(x[:3], x[3:6], uu) - d0) / eps
    P = np.eye(3) - np.outer(u, u)
    C = np.zeros((9, 9))
    C[:3, :3], C[3:6, 3:6], C[6:, 6:] = Ch, Ck, su**2 * P
    return d0, float(np.sqrt(g @ C @ g))


def report_real(sides: list[Side], run: trc.Trc, asis: tuple[np.ndarray, np.ndarray]) -> str:
    out: list[str] = []
    n = run.times.size
    out += [
        f"Running trial: {n} frames at {run.rate:g} Hz. Kabsch fit residual per segment "
        "(the cluster's shape change against the static trial; RMS / largest, mm):",
        "",
    ]
    rows = []
    for sd in sides:
        for s, r in sd.fit_rms.items():
            if s == "pelvis" and sd is not sides[0]:
                continue
            label = s if s == "pelvis" else f"{sd.label} {s}"
            rows.append([label, f"{1000 * rms(r):.2f}", f"{1000 * np.max(r):.2f}"])
    out += [table(["segment", "RMS (mm)", "largest (mm)"], rows), ""]

    # estimates per span
    rows = []
    for sd in sides:
        for name, e in sd.est.items():
            if name.startswith("block"):
                continue
            if isinstance(e, str):
                rows.append([sd.label, name, "refused: " + e[:200], "", "", "", ""])
                continue
            h, k = e.edges["hip"], e.edges["knee"]
            noise = (
                f"hip {h.noise.get('sigma_rot_deg', float('nan')):.2f} deg / "
                f"{1000 * h.noise.get('sigma_trans', float('nan')):.2f} mm, knee "
                f"{k.noise.get('sigma_rot_deg', float('nan')):.2f} deg / "
                f"{1000 * k.noise.get('sigma_trans', float('nan')):.2f} mm"
            )
            rows.append(
                [
                    sd.label,
                    name,
                    _pm(h.position_in["pelvis"], h.position_cov_in["pelvis"]),
                    ", ".join(f"{v:.3f}" for v in k.axis_in["thigh"])
                    + f" ± {k.axis_std_deg_in['thigh']:.2f} deg",
                    _pm(k.position_in["thigh"], k.position_cov_in["thigh"]),
                    f"{h.frames_rejected} / {k.frames_rejected}",
                    noise,
                ]
            )
    out += [
        "**Estimates** (pelvis frame: x forward, y up, z to the right, origin at the ASIS "
        "midpoint; thigh frame: the pelvis's axes in the static trial, origin at the thigh "
        "cluster's centroid there; value ± std, mm)",
        "",
        table(
            [
                "leg",
                "frames",
                "hip centre in pelvis (x, y, z)",
                "knee axis in thigh",
                "knee point in thigh (x, y, z)",
                "rejected hip / knee",
                "fitted noise",
            ],
            rows,
        ),
        "",
    ]
    warns = sorted(
        {
            f"{sd.label} {name}: {w}"
            for sd in sides
            for name, e in sd.est.items()
            if not isinstance(e, str) and name == "whole"
            for w in e.warnings
        }
    )
    if warns:
        out += ["Warnings (whole trial):", *(f"- {w}" for w in warns), ""]

    # halves
    rows = []
    for sd in sides:
        a, b = sd.est.get("first half"), sd.est.get("second half")
        if not isinstance(a, RigEstimate) or not isinstance(b, RigEstimate):
            rows.append([sd.label, "—", "—", "—"])
            continue

        def change(pa: np.ndarray, Ca: np.ndarray, pb: np.ndarray, Cb: np.ndarray) -> str:
            d, s = pb - pa, np.sqrt(np.diag(Ca + Cb))
            mah = float(np.sqrt(d @ np.linalg.pinv(Ca + Cb) @ d))
            return (
                ", ".join(f"{1000 * x:+.1f} ({x / y:+.1f})" for x, y in zip(d, s, strict=True))
                + f"; Mahalanobis {mah:.1f}"
            )

        ha, hb = a.edges["hip"], b.edges["hip"]
        ka, kb = a.edges["knee"], b.edges["knee"]
        ang = axis_angle_deg(ka.axis_in["thigh"], kb.axis_in["thigh"])
        s_ang = float(np.hypot(ka.axis_std_deg_in["thigh"], kb.axis_std_deg_in["thigh"]))
        rows.append(
            [
                sd.label,
                change(
                    ha.position_in["pelvis"],
                    ha.position_cov_in["pelvis"],
                    hb.position_in["pelvis"],
                    hb.position_cov_in["pelvis"],
                ),
                f"{ang:.2f} ({ang / s_ang:.1f})",
                change(
                    ka.position_in["thigh"],
                    ka.position_cov_in["thigh"],
                    kb.position_in["thigh"],
                    kb.position_cov_in["thigh"],
                ),
            ]
        )
    out += [
        "**Second half minus first half** (mm or deg; in brackets, in units of the combined "
        "std `sqrt(std1^2 + std2^2)`, per coordinate; Mahalanobis: `sqrt(d' (C1 + C2)^-1 d)`, "
        "3 dof)",
        "",
        table(["leg", "hip centre in pelvis", "knee axis (angle)", "knee point in thigh"], rows),
        "",
    ]

    # blocks
    blk = [(sd, [e for name, e in sd.est.items() if name.startswith("block")]) for sd in sides]
    if any(len(b) > 1 for _, b in blk):
        rows = []
        for sd, bl in blk:
            ok = [e for e in bl if isinstance(e, RigEstimate)]
            if len(ok) < 2:
                continue
            for what, get in (
                ("hip centre in pelvis", lambda e: (e.edges["hip"], "pelvis")),
                ("knee point in thigh", lambda e: (e.edges["knee"], "thigh")),
            ):
                P = np.array([get(e)[0].position_in[get(e)[1]] for e in ok])
                S_ = np.array([np.sqrt(np.diag(get(e)[0].position_cov_in[get(e)[1]])) for e in ok])
                spread = P.std(axis=0, ddof=1)
                rep = np.sqrt(np.mean(S_**2, axis=0))
                rows.append(
                    [
                        sd.label,
                        what,
                        ", ".join(f"{1000 * v:.2f}" for v in spread),
                        ", ".join(f"{1000 * v:.2f}" for v in rep),
                        ", ".join(f"{a / b:.1f}" for a, b in zip(spread, rep, strict=True)),
                    ]
                )
            U = np.array([_axis_pos(e.edges["knee"].axis_in["thigh"]) for e in ok])
            mean_u = U.mean(axis=0) / np.linalg.norm(U.mean(axis=0))
            angles = np.array([axis_angle_deg(u, mean_u) for u in U])
            spread_ang = float(np.sqrt(np.sum(angles**2) / (len(ok) - 1)))
            rep_ang = rms(np.array([e.edges["knee"].axis_std_deg_in["thigh"] for e in ok]))
            rows.append(
                [
                    sd.label,
                    "knee axis (deg, angle)",
                    f"{spread_ang:.2f}",
                    f"{rep_ang:.2f}",
                    f"{spread_ang / rep_ang:.1f}",
                ]
            )
        nb = max(len(b) for _, b in blk)
        out += [
            f"**{nb} consecutive blocks of {n // nb} frames**: the spread of the blocks' "
            "estimates (sample std over blocks, per coordinate x, y, z) against the std each "
            "block reports (RMS over blocks); a ratio near 1 means the std covers the "
            "block-to-block scatter",
            "",
            table(["leg", "quantity", "spread (mm)", "reported std (mm)", "spread / std"], rows),
            "",
        ]

    # left against right
    by = {sd.label: sd for sd in sides}
    if "R" in by and "L" in by:
        R_, L_ = by["R"].est.get("whole"), by["L"].est.get("whole")
        if isinstance(R_, RigEstimate) and isinstance(L_, RigEstimate):
            hr, hl = R_.edges["hip"], L_.edges["hip"]
            pr, Cr = hr.position_in["pelvis"], hr.position_cov_in["pelvis"]
            pl, Cl = mirror(hl.position_in["pelvis"]), mirror_cov(hl.position_cov_in["pelvis"])
            d, sd_ = pr - pl, np.sqrt(np.diag(Cr + Cl))
            kr, kl = R_.edges["knee"], L_.edges["knee"]
            ur, ul = kr.axis_in["thigh"], mirror(kl.axis_in["thigh"])
            ang = axis_angle_deg(ur, ul)
            s_ang = float(np.hypot(kr.axis_std_deg_in["thigh"], kl.axis_std_deg_in["thigh"]))
            dr, sr = hip_knee_distance(R_)
            dl, sl = hip_knee_distance(L_)
            rows = [
                [
                    "hip centre in pelvis (mm)",
                    _pm(pr, Cr),
                    _pm(pl, Cl),
                    ", ".join(
                        f"{1000 * x:+.1f} ({x / y:+.1f})" for x, y in zip(d, sd_, strict=True)
                    ),
                ],
                [
                    "knee axis in thigh",
                    ", ".join(f"{v:.3f}" for v in _axis_pos(ur)),
                    ", ".join(f"{v:.3f}" for v in _axis_pos(ul)),
                    f"{ang:.2f} deg ({ang / s_ang:.1f})",
                ],
                [
                    "hip centre to knee axis (mm)",
                    f"{1000 * dr:.1f} ± {1000 * sr:.1f}",
                    f"{1000 * dl:.1f} ± {1000 * sl:.1f}",
                    f"{1000 * (dr - dl):+.1f} ({(dr - dl) / np.hypot(sr, sl):+.1f})",
                ],
            ]
            out += [
                "**Right against left** (whole trial; the left side mirrored onto the right by "
                "changing the sign of its lateral coordinate z in the pelvis and thigh frames, "
                "which share the static pelvis's axes; axes compared up to sign; in brackets, "
                "in units of the combined std)",
                "",
                table(["quantity", "right", "left (mirrored)", "right - left"], rows),
                "",
            ]
            # frame-free: the distance between the hip centres; and a regression from the
            # ASIS width, as a landmark-based reference (not the truth)
            dh = hr.position_in["pelvis"] - hl.position_in["pelvis"]
            ih = float(np.linalg.norm(dh))
            s_ih = float(np.sqrt(dh @ (Cr + hl.position_cov_in["pelvis"]) @ dh)) / ih
            iaw = float(np.linalg.norm(asis[0] - asis[1]))
            bell = iaw * np.array([-0.19, -0.30, 0.36])
            # a small turn of the marker-made pelvis frame moves the two hips' x (about y)
            # and y (about x) in opposite directions: the turn that explains right - left
            zbar = 0.5 * (pr[2] + pl[2])
            out += [
                f"Frame-free: the hip centres are {1000 * ih:.1f} ± {1000 * s_ih:.1f} mm apart "
                f"(ASIS markers {1000 * iaw:.1f} mm apart; Bell et al.'s regression, hip "
                f"centre at (-0.19, -0.30, +-0.36) x the ASIS width from their midpoint, gives "
                f"({', '.join(f'{1000 * v:.1f}' for v in bell)}) mm and "
                f"{1000 * 2 * bell[2]:.1f} mm apart). The right - left differences in x and y "
                f"are what a turn of the marker-made pelvis frame by "
                f"{np.degrees(d[0] / (2 * zbar)):+.1f} deg about y and "
                f"{np.degrees(-d[1] / (2 * zbar)):+.1f} deg about x would make (an ASIS marker "
                "placed a few mm off symmetry does this).",
                "",
            ]
    # the knee against the static trial's epicondyle markers
    rows = []
    for sd in sides:
        whole = sd.est.get("whole")
        if not isinstance(whole, RigEstimate):
            continue
        k = whole.edges["knee"]
        lat, med = sd.epicondyles
        u_epi = (lat - med) / np.linalg.norm(lat - med)
        mid = 0.5 * (lat + med)
        u = k.axis_in["thigh"]
        dist = line_distance(mid, k.position_in["thigh"], u)
        rows.append(
            [
                sd.label,
                f"{1000 * np.linalg.norm(lat - med):.1f}",
                f"{axis_angle_deg(u, u_epi):.2f}",
                f"{1000 * dist:.1f}",
                f"{1000 * float((mid - k.position_in['thigh']) @ u):+.1f}",
            ]
        )
    if rows:
        out += [
            "**The functional knee against the static trial's epicondyle markers** "
            "(`Knee.Lat`, `Knee.Med`, in the thigh frame; a landmark on the skin, not the "
            "truth)",
            "",
            table(
                [
                    "leg",
                    "epicondyle width (mm)",
                    "axis angle to epicondylar axis (deg)",
                    "epicondyle midpoint to functional axis (mm)",
                    "midpoint along the axis from the knee point (mm)",
                ],
                rows,
            ),
        ]
    return "\n".join(out)


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--seeds", type=int, default=30, help="simulated seeds (parts 1-3)")
    ap.add_argument("--frames", type=int, default=300, help="frames per simulated trial")
    ap.add_argument(
        "--slide-mm",
        type=float,
        default=5.0,
        help="skin-marker error for part 3 (mocap_sim's slide_mm); 0 skips part 3",
    )
    ap.add_argument("--pelvis-turn-deg", type=float, default=2.0, help="hip trial's pelvis turn")
    ap.add_argument(
        "--turns",
        default="2,5,10,20",
        help="pelvis turns (deg) for the shared / separate sweep; empty skips it",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", type=Path, default=DATA, help="folder of the OpenSim TRC files")
    ap.add_argument("--blocks", type=int, default=5, help="consecutive blocks (real data)")
    ap.add_argument("--skip-sim", action="store_true")
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--out", type=Path, help="also write the Markdown report here")
    args = ap.parse_args(argv)
    if args.seeds < 2:
        ap.error("--seeds: at least 2")

    t_start = time.perf_counter()
    load_start = load()
    parts = [f"Date: {dt.datetime.now().astimezone().isoformat(timespec='seconds')}", ""]
    if not args.skip_sim:
        for title, slide in (
            ("Simulated motion capture, independent noise per frame", 0.0),
            (f"Simulated motion capture, skin-marker error {args.slide_mm:g} mm", args.slide_mm),
        ):
            if slide == 0.0 and title.endswith("mm"):
                continue
            log(title)
            S = run_sim(args.seeds, args.frames, slide, args.pelvis_turn_deg, args.seed)
            parts += [
                f"## {title}",
                "",
                f"{args.frames} frames per trial at 60 Hz, pose noise 0.5 deg / 1 mm per axis, "
                f"pelvis turn {args.pelvis_turn_deg:g} deg, seeds {args.seed}:0-"
                f"{args.seeds - 1}"
                + (f", slide_mm {slide:g} on the femur (hip) and tibia (knee)" if slide else "")
                + ".",
                "",
                report_sim(S, args.seeds),
                "",
            ]
        turns = [float(v) for v in args.turns.split(",") if v.strip()]
        if turns:
            log("pelvis turn sweep")
            parts += [
                "## Hip centre against the pelvis's turn (independent noise)",
                "",
                f"Seeds {args.seed}:0-{args.seeds - 1}, {args.frames} frames, pose noise "
                "0.5 deg / 1 mm per axis; the hip trial of part 1 with another pelvis turn.",
                "",
                run_turns(turns, args.seeds, args.frames, args.seed),
                "",
            ]
    if not args.skip_real:
        log("real data")
        run = trc.read_trc(args.data / "subject02_running.trc")
        ref = trc.reference_positions(trc.read_trc(args.data / "subject02_static.trc"))
        sides = [solve_side(run, ref, s, args.blocks) for s in ("R", "L")]
        T_pel = trc.segment_track(run, ref, "pelvis", "R").T_lab_seg_ref
        asis = (trc.in_segment(T_pel, ref["R.ASIS"]), trc.in_segment(T_pel, ref["L.ASIS"]))
        parts += [
            "## Real data: OpenSim's Hamner running trial",
            "",
            report_real(sides, run, asis),
            "",
        ]
    parts += [
        f"Machine: {machine_info()}; load average (1, 5, 15 min) {load_start} at the start, "
        f"{load()} at the end; {time.perf_counter() - t_start:.0f} s in all.",
    ]
    text = "\n".join(parts)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
