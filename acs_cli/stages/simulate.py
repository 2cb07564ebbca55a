"""The paper's simulation study (section 5): the paper's estimators against ours.

For every noise level ``k = 0 .. levels-1`` (``sigma_rot = k/(levels-1) * max_rot_deg``,
``sigma_trans = k/(levels-1) * max_trans``, per axis, on every pose) and every trial, one
random rig (``|O_A|, |O_B|`` in [1, 2] m) performs three motions of ``frames`` poses each:
a fixed-joint motion (Algorithm II), a general motion in one shared world (Algorithm I)
and a general motion with each camera in its own world (Algorithms III and IV). Both
methods see the same noisy poses. Scenarios:

``overlap``
    the joint from the shared-world motion (Algorithm I; the paper's figure of the joint).
``fixed_joint``
    the joint in A and in B from the fixed-joint motion (Algorithm II), with the
    Cramer-Rao bound of the joint for comparison.
``relpose``
    the joint from the fixed-joint motion by the same method, then the relative pose from
    the general motion (Algorithm III): the paper's joint feeds the paper's relpose with an
    exact prior, ours feeds ours with its covariances.
``unknown_scale``
    as ``relpose`` with both motions' translations scaled by ``mu_a``, ``mu_b`` (uniform
    in [0.5, 5]; the noise is added in metres before scaling): the fixed-joint joint comes
    out in each camera's units, the relative pose and ``phi_ba = mu_b / mu_a`` follow
    (Algorithm IV).

Error measures (the paper's): ``joint_err`` eq. (err),
``|O_A - Ô_A| / (2|O_A|) + |O_B - Ô_B| / (2|O_B|)``; ``rot_err_deg`` eq. (rot_err), the root
of the summed squared roll, pitch and yaw differences of ``R_a_b`` (each wrapped to
[-180, 180)); ``trans_err`` eq. (trans_err), ``|t_a_b - t̂_a_b| / |t_a_b|`` with ``t_a_b`` the
position of B in A (the paper's ``~T_BA``; under unknown scale ``t̂ / mu_b``); ``scale_err``
``|phi - phî| / phi``. Besides: ``joint_rms_err`` ``sqrt(|ô_a - o_a|^2 + |ô_b - o_b|^2)``
(metres), ``crlb_joint_rms`` the square root of the bound's summed traces for A and B, and
``rot_angle_err_deg`` the angle of ``R_a_b^T R̂_a_b`` (free of the Euler angles' gimbal lock).

A trial whose motion an estimator finds degenerate (:class:`DegenerateMotionError`) is a
failure row: its error text is kept and its measures are NaN; the summaries count failures
and average the other trials.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core import se3
from acs_cli.core.crlb import crlb_overlap, crlb_pivot
from acs_cli.core.joint import JointEstimate, estimate_joint_fixed
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.paper import algorithm_2_fixed_joint
from acs_cli.core.relpose import JointPrior, RelposeEstimate, estimate_relpose
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.atomic import atomic_path
from sample_data_gen.acs_sim import (
    Sequence as MotionSequence,
)
from sample_data_gen.acs_sim import (
    SyntheticRig,
    add_pose_noise,
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
)

__all__ = [
    "FIGURES",
    "MEASURES",
    "METHODS",
    "SCENARIOS",
    "TRIAL_COLUMNS",
    "SimulationConfig",
    "run_simulate",
    "run_study",
    "summarise",
    "write_study",
]

#: Scenarios of the study, in the paper's order.
SCENARIOS = ("overlap", "fixed_joint", "relpose", "unknown_scale")
#: The two estimators compared: as published, and ours.
METHODS = ("paper", "refined")
#: Per-trial error measures (NaN where a scenario does not define one).
MEASURES = (
    "joint_err",
    "joint_rms_err",
    "crlb_joint_rms",
    "rot_err_deg",
    "rot_angle_err_deg",
    "trans_err",
    "scale_err",
)
#: Columns of ``trials.csv`` (the keys of every row :func:`run_study` returns).
TRIAL_COLUMNS = (
    "scenario",
    "method",
    "level",
    "rot_noise_deg",
    "trans_noise",
    "trial",
    *MEASURES,
    "phi_true",
    "phi_hat",
    "error",
)
#: The paper's figures: file stem, scenario, measure, title, y label.
FIGURES = (
    ("fig05_joint_overlap", "overlap", "joint_err", "Joint, overlapping views", "joint error"),
    ("fig06_joint_fixed_joint", "fixed_joint", "joint_err", "Joint, fixed-joint motion",
     "joint error"),
    ("fig07_relpose_rotation", "relpose", "rot_err_deg", "Relative rotation R_BA",
     "rotation error (deg)"),
    ("fig08_relpose_translation", "relpose", "trans_err", "Relative translation T_BA",
     "relative translation error"),
    ("fig09_unknown_scale_joint", "unknown_scale", "joint_err", "Joint, unknown scale factors",
     "joint error"),
    ("fig10_unknown_scale_rotation", "unknown_scale", "rot_err_deg",
     "Relative rotation R_BA, unknown scale factors", "rotation error (deg)"),
    ("fig11_unknown_scale_translation", "unknown_scale", "trans_err",
     "Relative translation T_BA, unknown scale factors", "relative translation error"),
    ("fig12_scale_factor", "unknown_scale", "scale_err", "Relative scale factor phi_BA",
     "relative scale error"),
)  # fmt: skip

_METHOD_LABELS = {"paper": "paper (Chen & Wong)", "refined": "ours (refined)"}
#: Range of the unknown scales (the paper's section 5).
MU_RANGE = (0.5, 5.0)


@dataclass(frozen=True)
class SimulationConfig:
    """Design of the study.

    Attributes
    ----------
    trials : int
        Random rigs per noise level.
    frames : int
        Poses per motion.
    levels : int
        Noise levels ``k/(levels-1) * (max_rot_deg, max_trans)``, ``k = 0 .. levels-1``.
    max_rot_deg, max_trans : float
        Largest rotation (degrees) and translation (metres) noise, per axis.
    seed : int
        Trial ``t`` at level ``k`` draws from ``default_rng([seed, k, t])``.
    scenarios : tuple of str
        Any of :data:`SCENARIOS`.
    """

    trials: int = 100
    frames: int = 30
    levels: int = 9
    max_rot_deg: float = 2.4
    max_trans: float = 0.1
    seed: int = 0
    scenarios: tuple[str, ...] = SCENARIOS

    def __post_init__(self) -> None:
        if self.trials < 1:
            raise InputError(f"trials must be at least 1, got {self.trials}")
        if self.frames < 5:
            raise InputError(f"frames must be at least 5, got {self.frames}")
        if self.levels < 2:
            raise InputError(
                f"levels must be at least 2 (noise 0 and the maximum), got {self.levels}"
            )
        if not (self.max_rot_deg >= 0 and self.max_trans >= 0):
            raise InputError("max_rot_deg and max_trans must not be negative")
        if self.seed < 0:
            raise InputError(f"seed must not be negative, got {self.seed}")
        unknown = [s for s in self.scenarios if s not in SCENARIOS]
        if unknown or not self.scenarios:
            raise InputError(
                f"unknown scenarios {unknown}; choose from {', '.join(SCENARIOS)}"
                if unknown
                else "no scenario selected"
            )
        object.__setattr__(self, "scenarios", tuple(self.scenarios))

    def noise_levels(self) -> list[tuple[float, float]]:
        """``(sigma_rot_deg, sigma_trans)`` of each level."""
        steps = self.levels - 1
        return [  # rounded so that 3/4 of 2.4 deg is 1.8, not 1.7999999999999998
            (round(k * self.max_rot_deg / steps, 12), round(k * self.max_trans / steps, 12))
            for k in range(self.levels)
        ]


# ----------------------------------------------------------------------------- one trial


@dataclass(frozen=True)
class _Trial:
    """One random rig, its three true motions, their noisy poses and the unknown scales."""

    rig: SyntheticRig
    fixed: MotionSequence
    overlap: MotionSequence
    general: MotionSequence
    noisy: dict[str, tuple[FloatArray, FloatArray]]
    mu_a: float
    mu_b: float
    sigma_rot_deg: float
    sigma_trans: float


def _make_trial(config: SimulationConfig, level: int, trial: int) -> _Trial:
    """Draw a trial; the draws do not depend on which scenarios are run."""
    rng = np.random.default_rng([config.seed, level, trial])
    rot, trans = config.noise_levels()[level]
    rig = make_rig(rng)
    fixed = fixed_joint_sequence(rng, rig, config.frames)
    overlap = general_sequence(rng, rig, config.frames, shared_world=True)
    general = general_sequence(rng, rig, config.frames)
    noisy = {
        name: (
            add_pose_noise(rng, seq.T_wa_a, rot, trans),
            add_pose_noise(rng, seq.T_wb_b, rot, trans),
        )
        for name, seq in (("fixed", fixed), ("overlap", overlap), ("general", general))
    }
    mu_a, mu_b = (float(v) for v in rng.uniform(*MU_RANGE, size=2))
    return _Trial(rig, fixed, overlap, general, noisy, mu_a, mu_b, rot, trans)


def _wrap_deg(d: FloatArray) -> FloatArray:
    """Angles wrapped to [-180, 180)."""
    return np.asarray((np.asarray(d) + 180.0) % 360.0 - 180.0)


def _joint_measures(
    rig: SyntheticRig, o_a_hat: FloatArray, o_b_hat: FloatArray | None
) -> dict[str, float]:
    if o_b_hat is None:  # never for the scenarios of the study
        raise ValueError("the study needs the joint in both cameras")
    ea = float(np.linalg.norm(np.asarray(o_a_hat) - rig.o_a))
    eb = float(np.linalg.norm(np.asarray(o_b_hat) - rig.o_b))
    return {
        "joint_err": ea / (2 * float(np.linalg.norm(rig.o_a)))
        + eb / (2 * float(np.linalg.norm(rig.o_b))),
        "joint_rms_err": math.hypot(ea, eb),
    }


def _relpose_measures(
    seq: MotionSequence, est: RelposeEstimate, mu_b: float = 1.0
) -> dict[str, float]:
    T_a_b = seq.T_a_b[0]
    R_hat = est.T_a_b[:3, :3]
    d_rpy = _wrap_deg(se3.rpy_deg_from_matrix(R_hat) - se3.rpy_deg_from_matrix(T_a_b[:3, :3]))
    t_true = T_a_b[:3, 3]
    t_hat = est.translation_b_in_a / mu_b
    return {
        "rot_err_deg": float(np.sqrt(np.sum(d_rpy**2))),
        "rot_angle_err_deg": float(
            np.degrees(np.linalg.norm(se3.rotvec_from_matrix(T_a_b[:3, :3].T @ R_hat)))
        ),
        "trans_err": float(np.linalg.norm(t_true - t_hat) / np.linalg.norm(t_true)),
    }


def _crlb_rms(trial: _Trial, scenario: str) -> float:
    """Root of the summed traces of the joint's bound in A and B (0 without noise)."""
    s_rot, s_trans = np.radians(trial.sigma_rot_deg), trial.sigma_trans
    if s_rot == 0.0 and s_trans == 0.0:
        return 0.0
    rig = trial.rig
    if scenario == "overlap":
        seq = trial.overlap
        C = crlb_overlap(seq.T_wa_a, seq.T_wb_b, rig.o_a, rig.o_b, s_rot, s_trans)
        return float(np.sqrt(np.trace(C)))
    seq = trial.fixed
    Ca = crlb_pivot(seq.T_wa_a, rig.o_a, s_rot, s_trans)
    Cb = crlb_pivot(seq.T_wb_b, rig.o_b, s_rot, s_trans)
    return float(np.sqrt(np.trace(Ca) + np.trace(Cb)))


class _TrialRunner:
    """Evaluates the scenarios of one trial, sharing the fixed-joint estimates."""

    def __init__(self, trial: _Trial):
        self.trial = trial
        self._fixed: dict[tuple[str, bool], JointEstimate | DegenerateMotionError] = {}

    def _poses(self, name: str, scaled: bool) -> tuple[FloatArray, FloatArray]:
        Ta, Tb = self.trial.noisy[name]
        if not scaled:
            return Ta, Tb
        return scale_translations(Ta, self.trial.mu_a), scale_translations(Tb, self.trial.mu_b)

    def fixed_joint(self, method: str, scaled: bool) -> JointEstimate:
        key = (method, scaled)
        if key not in self._fixed:
            try:
                fixed = algorithm_2_fixed_joint if method == "paper" else estimate_joint_fixed
                self._fixed[key] = fixed(*self._poses("fixed", scaled))
            except DegenerateMotionError as exc:
                self._fixed[key] = exc
        out = self._fixed[key]
        if isinstance(out, DegenerateMotionError):
            raise out
        return out

    def _relpose(self, method: str, scaled: bool) -> RelposeEstimate:
        joint = self.fixed_joint(method, scaled)
        if method == "paper":
            prior = JointPrior(joint.position_in_a, joint.position_in_b)
        else:
            prior = JointPrior(
                joint.position_in_a, joint.position_in_b, joint.covariance_a, joint.covariance_b
            )
        return estimate_relpose(
            *self._poses("general", scaled), prior, unknown_scale=scaled, method=method
        )

    def evaluate(self, scenario: str, method: str) -> dict[str, float]:
        t = self.trial
        if scenario == "overlap":
            est = estimate_joint_overlap(*self._poses("overlap", False), method=method)
            out = _joint_measures(t.rig, est.position_in_a, est.position_in_b)
            out["crlb_joint_rms"] = _crlb_rms(t, "overlap")
            return out
        if scenario == "fixed_joint":
            est = self.fixed_joint(method, False)
            out = _joint_measures(t.rig, est.position_in_a, est.position_in_b)
            out["crlb_joint_rms"] = _crlb_rms(t, "fixed_joint")
            return out
        if scenario == "relpose":
            rel = self._relpose(method, False)
            out = _joint_measures(t.rig, rel.position_in_a, rel.position_in_b)
            out.update(_relpose_measures(t.general, rel))
            return out
        if scenario == "unknown_scale":
            rel = self._relpose(method, True)
            out = _joint_measures(t.rig, rel.position_in_a / t.mu_a, rel.position_in_b / t.mu_b)
            out.update(_relpose_measures(t.general, rel, t.mu_b))
            phi = t.mu_b / t.mu_a
            out["phi_true"] = phi
            out["phi_hat"] = float(rel.phi_ba)
            out["scale_err"] = abs(phi - float(rel.phi_ba)) / phi
            return out
        raise ValueError(f"unknown scenario {scenario!r}")


def _empty_row(
    scenario: str, method: str, level: int, noise: tuple[float, float], trial: int
) -> dict[str, Any]:
    row: dict[str, Any] = {c: math.nan for c in TRIAL_COLUMNS}
    row.update(
        scenario=scenario,
        method=method,
        level=level,
        rot_noise_deg=float(noise[0]),
        trans_noise=float(noise[1]),
        trial=trial,
        error="",
    )
    return row


def run_study(
    config: SimulationConfig, progress: Callable[[int, int], None] | None = None
) -> list[dict[str, Any]]:
    """Run the study: one row per scenario, method, noise level and trial.

    Parameters
    ----------
    config : SimulationConfig
    progress : callable, optional
        Called as ``progress(done, total)`` after each trial (all its scenarios), with
        ``total = levels * trials``.

    Returns
    -------
    list of dict
        Rows with the keys :data:`TRIAL_COLUMNS`; ``error`` is empty, or the message of a
        :class:`DegenerateMotionError` (then the measures are NaN).
    """
    levels = config.noise_levels()
    total = len(levels) * config.trials
    rows: list[dict[str, Any]] = []
    done = 0
    for level, noise in enumerate(levels):
        for trial_index in range(config.trials):
            runner = _TrialRunner(_make_trial(config, level, trial_index))
            for scenario in config.scenarios:
                for method in METHODS:
                    row = _empty_row(scenario, method, level, noise, trial_index)
                    try:
                        row.update(runner.evaluate(scenario, method))
                    except DegenerateMotionError as exc:
                        row["error"] = exc.one_line()
                    rows.append(row)
            done += 1
            if progress is not None:
                progress(done, total)
    return rows


# ----------------------------------------------------------------------------- summaries


def _finite(values: Iterable[Any]) -> FloatArray:
    arr = np.asarray([float(v) for v in values], dtype=float)
    return arr[np.isfinite(arr)]


def _mean_std(values: FloatArray) -> tuple[float, float]:
    if values.size == 0:
        return math.nan, math.nan
    return float(np.mean(values)), float(np.std(values))


def _rms(values: FloatArray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def summarise(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Mean and STD of each measure per scenario, method and noise level.

    Failed trials (non-empty ``error``) are counted in ``n_failed`` and left out of the
    statistics. Keys: ``scenario, method, level, rot_noise_deg, trans_noise, n_trials,
    n_failed``, then ``<measure>_mean`` and ``<measure>_std`` for every measure of
    :data:`MEASURES`, ``rms_over_crlb`` (RMS of ``joint_rms_err`` over RMS of
    ``crlb_joint_rms``; NaN without noise or without a bound) and ``scale_accuracy``
    (``1 - mean(scale_err)``).
    """
    groups: dict[tuple[str, str, int], list[Mapping[str, Any]]] = {}
    for row in rows:
        key = (str(row["scenario"]), str(row["method"]), int(row["level"]))
        groups.setdefault(key, []).append(row)
    s_order = {s: i for i, s in enumerate(SCENARIOS)}
    m_order = {m: i for i, m in enumerate(METHODS)}
    out: list[dict[str, Any]] = []
    for key in sorted(
        groups, key=lambda k: (s_order.get(k[0], len(s_order)), k[0], k[2], m_order.get(k[1], 9))
    ):
        group = groups[key]
        ok = [r for r in group if not r.get("error")]
        summary: dict[str, Any] = {
            "scenario": key[0],
            "method": key[1],
            "level": key[2],
            "rot_noise_deg": float(group[0]["rot_noise_deg"]),
            "trans_noise": float(group[0]["trans_noise"]),
            "n_trials": len(group),
            "n_failed": len(group) - len(ok),
        }
        for m in MEASURES:
            summary[f"{m}_mean"], summary[f"{m}_std"] = _mean_std(_finite(r[m] for r in ok))
        err_rms = _rms(_finite(r["joint_rms_err"] for r in ok))
        bound_rms = _rms(_finite(r["crlb_joint_rms"] for r in ok))
        summary["rms_over_crlb"] = (
            err_rms / bound_rms if math.isfinite(bound_rms) and bound_rms > 0 else math.nan
        )
        summary["scale_accuracy"] = 1.0 - summary["scale_err_mean"]
        out.append(summary)
    return out


# ----------------------------------------------------------------------------- files


def _csv_value(v: Any) -> str:
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return str(v)


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(columns)
            for row in rows:
                w.writerow([_csv_value(row.get(c, "")) for c in columns])


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _write_figure(
    path: Path,
    summary: Sequence[Mapping[str, Any]],
    scenario: str,
    measure: str,
    title: str,
    ylabel: str,
) -> bool:
    """One figure, panels (a) mean and (b) STD vs noise; False if the scenario is absent."""
    rows = [r for r in summary if r["scenario"] == scenario]
    if not rows:
        return False
    plt = _pyplot()
    levels = sorted({int(r["level"]) for r in rows})
    noise = {int(r["level"]): (r["rot_noise_deg"], r["trans_noise"]) for r in rows}
    x = np.arange(len(levels), dtype=float)  # evenly spaced levels, labelled with both noises
    ticks = [f"{noise[k][0]:.2g}°\n{noise[k][1]:.3g} m" for k in levels]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    try:
        for ax, stat, panel in zip(axes, ("mean", "std"), ("(a) mean", "(b) STD"), strict=True):
            for method in METHODS:
                by_level = {int(r["level"]): r for r in rows if r["method"] == method}
                if not by_level:
                    continue
                y = [float(by_level[k][f"{measure}_{stat}"]) if k in by_level else math.nan
                     for k in levels]  # fmt: skip
                ax.plot(x, y, marker="o", label=_METHOD_LABELS.get(method, method))
            ax.set_title(f"{panel} {ylabel}")
            ax.set_xticks(x)
            ax.set_xticklabels(ticks, fontsize=8)
            ax.set_xlabel("noise per axis: rotation (deg) / translation (m)")
            ax.set_ylabel(f"{stat.upper() if stat == 'std' else stat} {ylabel}")
            ax.grid(True, alpha=0.3)
            ax.legend()
        fig.suptitle(title)
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=100)
    finally:
        plt.close(fig)
    return True


def write_study(out_dir: str | Path, rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Write ``trials.csv``, ``summary.csv`` and the paper's figures into ``out_dir``.

    Returns
    -------
    dict
        ``trials_csv``, ``summary_csv`` (paths) and ``figures`` (list of PNG paths; a
        figure is left out when its scenario was not run).
    """
    out = Path(out_dir)
    summary = summarise(rows)
    trials_csv = out / "trials.csv"
    summary_csv = out / "summary.csv"
    _write_csv(trials_csv, rows, TRIAL_COLUMNS)
    columns = list(summary[0]) if summary else ["scenario", "method", "level"]
    _write_csv(summary_csv, summary, columns)
    figures = []
    for stem, scenario, measure, title, ylabel in FIGURES:
        path = out / f"{stem}.png"
        if _write_figure(path, summary, scenario, measure, title, ylabel):
            figures.append(path)
    return {"trials_csv": trials_csv, "summary_csv": summary_csv, "figures": figures}


def _headline(summary: Sequence[Mapping[str, Any]], top: int) -> dict[str, Any]:
    """Mean errors at the highest noise, RMS/CRLB and scale accuracy per level."""
    main = {
        "overlap": ("joint_err",),
        "fixed_joint": ("joint_err",),
        "relpose": ("rot_err_deg", "trans_err"),
        "unknown_scale": ("rot_err_deg", "trans_err", "scale_err"),
    }
    at_top: dict[str, dict[str, float]] = {}
    ratio: dict[str, list[float]] = {}
    accuracy: dict[str, list[float]] = {}
    failed = 0
    for r in summary:
        failed += int(r["n_failed"])
        scen, method = str(r["scenario"]), str(r["method"])
        if int(r["level"]) == top:
            at_top.setdefault(f"{scen}/{method}", {}).update(
                {f"{m}_mean": float(r[f"{m}_mean"]) for m in main.get(scen, ())}
            )
        if scen == "fixed_joint":
            ratio.setdefault(method, []).append(float(r["rms_over_crlb"]))
        if scen == "unknown_scale":
            accuracy.setdefault(method, []).append(float(r["scale_accuracy"]))
    return {
        "mean_errors_at_max_noise": at_top,
        "fixed_joint_rms_over_crlb": ratio,
        "scale_accuracy": accuracy,
        "failed_trials": failed,
    }


def run_simulate(
    out_dir: str | Path,
    config: SimulationConfig,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Run the study, write its files (and ``study.yaml``) and return a summary for the CLI.

    Returns
    -------
    dict
        ``out_dir``, ``trials_csv``, ``summary_csv``, ``figures``, ``study_yaml`` (paths as
        strings), ``elapsed_s``, ``n_rows``, ``config`` and ``headline``: mean errors at the
        highest noise level per scenario/method, the fixed-joint RMS/CRLB ratio and the
        scale accuracy per level (lists in level order), and the number of failed trials.
    """
    out = Path(out_dir)
    t0 = time.perf_counter()
    rows = run_study(config, progress)
    written = write_study(out, rows)
    elapsed = time.perf_counter() - t0
    headline = _headline(summarise(rows), config.levels - 1)
    cfg = dataclasses.asdict(config)
    study_yaml = out / "study.yaml"
    header = make_header(
        "simulation",
        inputs={},
        method="Chen & Wong section 5 simulation: paper's estimators vs refined (acscal)",
        units={"length": "metres", "angles": "deg", "errors": "see docstring of "
               "acs_cli.stages.simulate (joint_err, trans_err, scale_err relative)"},
        frames={"relative_pose": "R_a_b / t_a_b at reference instant 0"},
    )  # fmt: skip
    write_yaml_artifact(
        study_yaml,
        header,
        {
            "config": cfg,
            "noise_levels": config.noise_levels(),
            "elapsed_s": elapsed,
            "files": {
                "trials_csv": written["trials_csv"].name,
                "summary_csv": written["summary_csv"].name,
                "figures": [p.name for p in written["figures"]],
            },
            "headline": headline,
        },
    )
    return {
        "out_dir": str(out),
        "trials_csv": str(written["trials_csv"]),
        "summary_csv": str(written["summary_csv"]),
        "figures": [str(p) for p in written["figures"]],
        "study_yaml": str(study_yaml),
        "elapsed_s": elapsed,
        "n_rows": len(rows),
        "config": cfg,
        "headline": headline,
    }
