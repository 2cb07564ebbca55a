"""``make demo``: a synthetic ACS calibrated with the real ``acscal`` commands.

``python -m sample_data_gen.demo OUT_DIR`` writes the sample set (when missing), runs
``acscal joint`` and ``acscal relpose`` as a user would (paper's method and ours, known and
unknown scale, self-calibration) and prints each result beside the truth.

Then it calibrates from images: it renders the checkerboard image sample set into
``OUT_DIR/images`` (when missing), encodes the overlap scenario's two cameras as videos
(``images/overlap/cam_a.mkv``, lossless FFV1 at 10 fps), runs ``acscal run
configs/fixed_joint.yaml`` (image folders) and ``acscal run configs/overlap.yaml`` (the
videos: each frame's time is its presentation timestamp) (for an ``OUT_DIR`` other than the
repository's ``demo_out``, copies of the configs pointing at ``OUT_DIR`` are written to
``OUT_DIR/configs``) and prints the joint and the relative pose beside the rendered truth,
and the path of each run's HTML report (``acscal run`` writes ``report.html`` at its end).

Then an AprilGrid: it renders one camera filming Kalibr's 6x6 AprilGrid into
``OUT_DIR/aprilgrid`` (when missing; half the frames show only part of the grid), runs
``acscal intrinsics --target`` on it and prints the intrinsics beside the truth.

With ``--markerless`` (``make showcase`` runs ``--only markerless``), last, the markerless
showcase, minutes of structure from motion: it renders two cameras of a rig moving through a
textured room into ``OUT_DIR/markerless`` (when missing), builds each camera's trajectory by
structure from motion (``acscal poses --sfm``, intrinsics from a calibration: here the
renderer's, written as ``acscal intrinsics`` files), calibrates the pair with ``acscal
relpose --self-calibrate --unknown-scale`` and prints the scale factor and the relative pose
beside the truth.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from acs_cli.core import se3
from sample_data_gen.render import render_sample_set
from sample_data_gen.writer import write_sample_set

ACSCAL = Path(sys.executable).with_name("acscal")
REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "configs"
RUN_CONFIGS = ("fixed_joint", "overlap")
console = Console(highlight=False, width=None if sys.stdout.isatty() else 120)


Command = tuple[str | Path, ...]


def _execute(args: Command) -> subprocess.CompletedProcess[str]:
    cmd = [str(ACSCAL), *map(str, args)]
    env = dict(os.environ, COLUMNS=str(console.width))
    return subprocess.run(cmd, capture_output=True, text=True, env=env)


def _report(args: Command, res: subprocess.CompletedProcess[str], show: bool = False) -> None:
    console.print(f"[bold]$ acscal {' '.join(map(str, args))}[/]")
    if res.returncode != 0:
        console.print(res.stdout + res.stderr, markup=False)
        raise SystemExit(f"demo: acscal failed with exit code {res.returncode}")
    if show:
        console.print(res.stdout.rstrip(), markup=False)


def _run(*args: str | Path, show: bool = False) -> None:
    _report(args, _execute(args), show)


def _run_chains(chains: Sequence[Sequence[Command]]) -> None:
    """Run each chain's commands in order, the chains side by side (two at a time: this
    machine's cores), and print every command as :func:`_run` does, in the chains' order.
    A failed command stops its chain; the first failure, in that order, ends the demo."""

    def chain(cmds: Sequence[Command]) -> list[subprocess.CompletedProcess[str]]:
        done = []
        for args in cmds:
            done.append(_execute(args))
            if done[-1].returncode != 0:
                break
        return done

    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(chain, chains))
    for cmds, done in zip(chains, results, strict=True):
        for args, res in zip(cmds, done, strict=False):
            _report(args, res)


def _load(path: Path) -> dict[str, Any]:
    return dict(yaml.safe_load(path.read_text()))


def _v(x: Any, digits: int = 3) -> str:
    return "[" + ", ".join(f"{float(v):+.{digits}f}" for v in np.ravel(x)) + "]"


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must look like 640x480, got {text!r}") from None
    return w, h


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sample_data_gen.demo", description=__doc__)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=20, help="rendered images per camera")
    ap.add_argument("--size", type=_size, default=(640, 480), metavar="WxH", help="image size")
    ap.add_argument("--no-images", action="store_true", help="skip the image-chain part")
    ap.add_argument("--no-target", action="store_true", help="skip the AprilGrid intrinsics part")
    ap.add_argument(
        "--markerless",
        action="store_true",
        help="also the markerless showcase (structure from motion: minutes; `make showcase`)",
    )
    ap.add_argument(
        "--no-markerless", action="store_true", help="leave the markerless showcase out (default)"
    )
    ap.add_argument(
        "--only",
        action="append",
        choices=PARTS,
        metavar="PART",
        help=f"run only this part (repeatable): {', '.join(PARTS)}",
    )
    args = ap.parse_args(argv)
    out: Path = args.out_dir
    parts = set(args.only or PARTS)
    if args.only is None:
        for flag, part in ((args.no_images, "images"), (args.no_target, "target")):
            if flag:
                parts.discard(part)
        if not args.markerless or args.no_markerless:
            parts.discard("markerless")
    if "trajectories" in parts:
        _trajectory_demo(out, args.seed)
    if "rig" in parts:
        _rig_demo(out, args.seed)
    if "images" in parts:
        _image_demo(out, args.seed, args.frames, args.size)
    if "target" in parts:
        _target_demo(out, args.seed)
    if "markerless" in parts:
        _markerless_demo(out, args.seed)
    return 0


#: The demo's parts, in the order they run (``--only``).
PARTS = ("trajectories", "rig", "images", "target", "markerless")


#: Frames of the AprilGrid demo (640x480; every other one shows 30-70 % of the grid).
TARGET_FRAMES = 20


def _target_demo(out: Path, seed: int) -> None:
    """Rendered AprilGrid sequence (partial views) -> acscal intrinsics --target."""
    from sample_data_gen.target_render import default_target, render_target_sequence

    console.rule("AprilGrid: acscal intrinsics --target on partial views")
    data = out / "aprilgrid"
    done = (data / "truth.yaml").is_file() and int(
        _load(data / "truth.yaml").get("n_frames", 0)
    ) == TARGET_FRAMES
    if not done:
        console.print(f"rendering a camera filming Kalibr's 6x6 AprilGrid into {data}")
        render_target_sequence(data, default_target("aprilgrid"), seed=seed, frames=TARGET_FRAMES)
    intr = out / "run_aprilgrid" / "intrinsics.yaml"
    _run(
        "intrinsics", _show(data / "images"), "--target", _show(data / "target.yaml"),
        "-o", _show(intr),
    )  # fmt: skip
    truth = _load(data / "truth.yaml")["camera"]
    est = _load(intr)
    K, K_true = np.asarray(est["camera_matrix"]), np.asarray(truth["camera_matrix"])
    D, D_true = np.asarray(est["distortion"]), np.asarray(truth["distortion"])
    table = Table(title="AprilGrid intrinsics: estimate beside the truth", title_justify="left")
    for col in ("quantity", "acscal", "truth", "error"):
        table.add_column(col)
    for name, i, j in (("fx", 0, 0), ("fy", 1, 1), ("cx", 0, 2), ("cy", 1, 2)):
        table.add_row(f"{name} (px)", f"{K[i, j]:.2f}", f"{K_true[i, j]:.2f}",
                      f"{K[i, j] - K_true[i, j]:+.3f} px")  # fmt: skip
    for k, name in enumerate(("k1", "k2")):
        table.add_row(name, f"{D[k]:+.5f}", f"{D_true[k]:+.5f}", f"{D[k] - D_true[k]:+.5f}")
    used = est["images"]
    table.add_row("views used (half partial)", f"{len(used['used'])}/{used['total']}", "", "")
    table.add_row("reprojection RMS (px)", f"{est['rms_px']:.4f}", "", "")
    console.print(table)


#: Frames per camera of the markerless demo (30 Hz, 640x480).
MARKERLESS_FRAMES = 60


def _markerless_demo(out: Path, seed: int) -> None:
    """Rendered textured video -> SfM trajectories -> relative pose and scale factor."""
    import dataclasses

    from acs_cli.io.artifacts import make_header
    from acs_cli.io.intrinsics import IntrinsicsArtifact
    from acs_cli.io.poses import PosesArtifact
    from acs_cli.io.relpose import RelposeArtifact
    from acs_cli.io.trajectory import read_trajectory
    from sample_data_gen.textured import render_markerless

    console.rule("Markerless: structure from motion, then acscal relpose --unknown-scale")
    data = out / "markerless"
    done = (data / "truth.yaml").is_file() and int(
        _load(data / "truth.yaml").get("n_frames", 0)
    ) == MARKERLESS_FRAMES
    if not done:
        console.print(f"rendering two cameras in a textured room into {data}")
        render_markerless(out, seed=seed, frames=MARKERLESS_FRAMES)
    truth = _load(data / "truth.yaml")
    run = out / "run_markerless"
    run.mkdir(parents=True, exist_ok=True)
    for cam in ("a", "b"):
        t = truth[f"cam_{cam}"]
        intr = IntrinsicsArtifact(
            model="pinhole",
            image_size=(int(t["image_size"][0]), int(t["image_size"][1])),
            camera_matrix=np.asarray(t["K"], dtype=float),
            distortion=np.asarray(t["dist"], dtype=float),
        )
        header = make_header(
            "intrinsics", {}, "the renderer's camera (a stand-in for acscal intrinsics)", {}, {}
        )
        dataclasses.replace(intr, header=header).save(run / f"intrinsics_{cam}.yaml")
        _run(
            "poses", _show(data / f"cam_{cam}"), "--sfm", "--intrinsics",
            _show(run / f"intrinsics_{cam}.yaml"), "--max-features", "2048",
            "-o", _show(run / f"poses_{cam}.npz"),
        )  # fmt: skip
    _run(
        "relpose", "--self-calibrate", "--unknown-scale", "--poses-a", _show(run / "poses_a.npz"),
        "--poses-b", _show(run / "poses_b.npz"), "-o", _show(run / "relpose.yaml"),
    )  # fmt: skip
    rel = RelposeArtifact.load(run / "relpose.yaml")
    truth_a, truth_b = (
        read_trajectory(data / "truth_a.tum", "tum"),
        read_trajectory(data / "truth_b.tum", "tum"),
    )
    reg = {c: PosesArtifact.load(run / f"poses_{c}.npz") for c in ("a", "b")}
    # SfM units: the mean distance between consecutive camera centres (of the registered
    # images); the truth's own, in metres, over the same images
    unit = {}
    for c, tr in (("a", truth_a), ("b", truth_b)):
        names = list(reg[c].trajectory.names)
        idx = [int("".join(ch for ch in n if ch.isdigit())) for n in names]
        centres = tr.T_world_cam[idx, :3, 3]
        unit[c] = float(np.mean(np.linalg.norm(np.diff(centres, axis=0), axis=1)))
    # the reference pair's frame: image names carry the frame index (the poses' time)
    k = round(float(rel.relative_pose.reference_timestamp_a or 0.0))
    T_b_a = se3.invert_transforms(truth_b.T_world_cam[k]) @ truth_a.T_world_cam[k]
    est = rel.relative_pose.T_b_a
    table = Table(title="markerless: estimate beside the truth", title_justify="left")
    for col in ("quantity", "acscal", "truth", "error"):
        table.add_column(col)
    for c in ("a", "b"):
        n_reg, n_all = len(reg[c]), len(reg[c].trajectory) + len(reg[c].skipped_images)
        table.add_row(f"camera {c.upper()} frames registered by SfM", f"{n_reg}/{n_all}", "", "")
    phi_true = unit["a"] / unit["b"]
    if rel.scale is None:
        raise SystemExit("demo: relpose --unknown-scale wrote no scale")
    phi = rel.scale.phi_ba
    table.add_row("phi_ba = mu_b / mu_a", f"{phi:.5f}", f"{phi_true:.5f}",
                  f"{100 * abs(phi / phi_true - 1):.2f}%")  # fmt: skip
    dR = float(se3.rotation_angle_deg(T_b_a[:3, :3].T @ est[:3, :3]))
    table.add_row("R_a_b roll, pitch, yaw (deg)", _v(rel.relative_pose.rpy_deg, 2),
                  _v(se3.rpy_deg_from_matrix(T_b_a[:3, :3].T), 2), f"{dR:.3f} deg")  # fmt: skip
    t_m = est[:3, 3] * unit["b"]  # B units to metres
    table.add_row("t_b_a (m, via the truth's B unit)", _v(t_m, 4), _v(T_b_a[:3, 3], 4),
                  f"{1000 * float(np.linalg.norm(t_m - T_b_a[:3, 3])):.1f} mm")  # fmt: skip
    console.print(table)
    console.print(f"relpose written to {_show(run / 'relpose.yaml')}")


def _trajectory_demo(out: Path, seed: int) -> None:
    data = out / "data"
    if not (data / "general_scaled" / "truth.yaml").exists():
        console.print(f"writing the sample data set into {data}")
        write_sample_set(data, seed=seed)
    res = out / "results"
    res.mkdir(parents=True, exist_ok=True)

    def poses(scn: str) -> list[str | Path]:
        return ["--poses-a", data / scn / "cam_a.tum", "--poses-b", data / scn / "cam_b.tum"]

    def commands(method: str) -> list[Command]:
        return [
            ("joint", "--fixed-joint", *poses("fixed_joint"), "--method", method,
             "-o", res / f"joint_fixed_{method}.yaml"),
            ("joint", "--overlap", *poses("overlap"), "--method", method,
             "-o", res / f"joint_overlap_{method}.yaml"),
            ("relpose", "--joint", res / f"joint_fixed_{method}.yaml", *poses("general"),
             "--method", method, "-o", res / f"relpose_{method}.yaml"),
            ("joint", "--fixed-joint", *poses("fixed_joint_scaled"), "--method", method,
             "-o", res / f"joint_fixed_scaled_{method}.yaml"),
            ("relpose", "--unknown-scale", "--joint", res / f"joint_fixed_scaled_{method}.yaml",
             *poses("general_scaled"), "--method", method,
             "-o", res / f"relpose_scaled_{method}.yaml"),
        ]  # fmt: skip

    selfcal: Command = (
        "relpose", "--self-calibrate", "--unknown-scale", *poses("general_scaled"),
        "-o", res / "relpose_selfcal_scaled.yaml",
    )  # fmt: skip
    # the paper's method and ours side by side (each chain: a joint, then the relative pose
    # that reads it); the self-calibration after the quicker paper's chain
    _run_chains([[*commands("paper"), selfcal], commands("refined")])

    truth = _load(data / "general" / "truth.yaml")
    truth_s = _load(data / "general_scaled" / "truth.yaml")
    mu_b = float(truth_s["scale"]["mu_b"])
    table = Table(title="acscal demo: estimates beside the truth (lengths in metres)")
    table.add_column("quantity")
    table.add_column("truth")
    table.add_column("paper's method")
    table.add_column("acscal (refined)")

    def both(name: str, key: str, scale: float = 1.0) -> tuple[str, str]:
        vals = []
        for m in ("paper", "refined"):
            doc = _load(res / f"{name}_{m}.yaml")
            node: Any = doc
            for k in key.split("."):
                node = node[k]
            vals.append(_v(np.asarray(node, dtype=float) / scale))
        return vals[0], vals[1]

    tj = truth["joint"]
    table.add_row("joint in A, fixed joint (Alg II)", _v(tj["position_in_a"]),
                  *both("joint_fixed", "joint.position_in_a"))  # fmt: skip
    table.add_row("joint in B, fixed joint (Alg II)", _v(tj["position_in_b"]),
                  *both("joint_fixed", "joint.position_in_b"))  # fmt: skip
    table.add_row("joint in A, overlap (Alg I)", _v(tj["position_in_a"]),
                  *both("joint_overlap", "joint.position_in_a"))  # fmt: skip
    tr = truth["relative_pose"]
    table.add_row("roll/pitch/yaw of R_a_b, deg (Alg III)", _v(tr["rpy_deg"], 2),
                  *both("relpose", "relative_pose.rpy_deg"))  # fmt: skip
    table.add_row("B's origin in A (Alg III)", _v(tr["translation_b_in_a"]),
                  *both("relpose", "relative_pose.translation_b_in_a"))  # fmt: skip
    table.add_row("B's origin in A, unknown scale (Alg IV)", _v(tr["translation_b_in_a"]),
                  *both("relpose_scaled", "relative_pose.translation_b_in_a", mu_b))  # fmt: skip
    table.add_row("phi_ba = mu_b / mu_a (Alg IV)", f"{truth_s['scale']['phi_ba']:.4f}",
                  *both("relpose_scaled", "scale.phi_ba"))  # fmt: skip
    sc = _load(res / "relpose_selfcal_scaled.yaml")
    sc_joint = np.asarray(sc["joint"]["position_in_a"]) / truth_s["scale"]["mu_a"]
    table.add_row("self-calibration: joint in A (A units / mu_a)", _v(tj["position_in_a"]),
                  "n/a", _v(sc_joint))  # fmt: skip
    table.add_row("self-calibration: phi_ba", f"{truth_s['scale']['phi_ba']:.4f}", "n/a",
                  f"{sc['scale']['phi_ba']:.4f}")  # fmt: skip
    console.print(table)
    console.print(f"artifacts in {res}")


# --------------------------------------------------------------------------- from images


def _rig_demo(out: Path, seed: int) -> None:
    """A five-camera rig (rigid, ball, hinge, rigid; one camera with unknown scale):
    ``acscal run configs/rig.yaml``, then every camera and joint beside the truth."""
    from acs_cli.io.rig import RigArtifact
    from sample_data_gen.writer import write_rig_recording

    console.rule("A rig of five cameras: acscal run configs/rig.yaml")
    rig_dir = out / "rig"
    if not (rig_dir / "truth.yaml").is_file():
        write_rig_recording(rig_dir, seed=seed)
    config = _config_for("rig", out)
    _run("run", config)
    doc = _load(config)
    run_dir = Path(os.path.normpath(config.parent / doc["output"]))
    rig = RigArtifact.load(run_dir / "rig.yaml")
    truth = _load(rig_dir / "truth.yaml")
    table = Table(title="rig: estimate beside the truth (metres, degrees)", title_justify="left")
    for col in ("quantity", "acscal", "truth", "error"):
        table.add_column(col)
    for name, cam in rig.cameras.items():
        T_true = np.asarray(truth["cameras"][name]["T_cam_ref"], dtype=float)
        T = cam.T_cam_ref
        dR = float(np.degrees(np.linalg.norm(se3.rotvec_from_matrix(T_true[:3, :3].T @ T[:3, :3]))))
        dt = float(np.linalg.norm(T_true[:3, 3] - T[:3, 3]))
        table.add_row(
            f"{name} T_cam_ref t", _v(T[:3, 3]), _v(T_true[:3, 3]), f"{dt:.4f} m, {dR:.3f} deg"
        )
        if cam.unknown_scale:
            s_true = float(truth["cameras"][name]["scale"])
            table.add_row(
                f"{name} scale",
                f"{cam.scale:.5f}",
                f"{s_true:.5f}",
                f"{100 * abs(cam.scale - s_true) / s_true:.2f}%",
            )
    for name, j in rig.joints.items():
        tj = truth["joints"][name]
        for c, pos in j.position_in.items():
            p_true = np.asarray(tj["position_in"][c], dtype=float)
            table.add_row(
                f"{name} ({j.type}) in {c}",
                _v(pos),
                _v(p_true),
                f"{float(np.linalg.norm(pos - p_true)):.4f} m",
            )
        for c, axis in j.axis_in.items():
            a_true = np.asarray(tj["axis_in"][c], dtype=float)
            ang = float(np.degrees(np.arccos(min(1.0, abs(float(axis @ a_true))))))
            table.add_row(f"{name} axis in {c}", _v(axis), _v(a_true), f"{ang:.3f} deg")
    console.print(table)
    console.print(f"rig written to {run_dir / 'rig.yaml'}")


def _images_ok(images: Path, frames: int, size: tuple[int, int]) -> bool:
    """Does ``images`` hold a complete rendered set of ``frames`` images of ``size``?"""
    for scn in ("overlap", "fixed_joint", "general"):
        truth = images / scn / "truth.yaml"
        if not truth.is_file():
            return False
        doc = _load(truth)
        if int(doc["n_frames"]) != frames or tuple(doc["image_size"]) != tuple(size):
            return False
    return True


#: The rendered scenario whose run reads video files (``configs/overlap.yaml``), and their
#: frame rate: each frame's time is its presentation timestamp.
VIDEO_SCENARIO, VIDEO_FPS = "overlap", 10.0


def _videos_for(images: Path) -> None:
    """Encode :data:`VIDEO_SCENARIO`'s image folders as lossless videos beside them
    (``cam_a.mkv``, FFV1), unless they are there and newer than the folders' images."""
    from sample_data_gen.video import folder_to_video

    for cam in ("cam_a", "cam_b"):
        folder = images / VIDEO_SCENARIO / cam
        video = folder.with_suffix(".mkv")
        newest = max(p.stat().st_mtime for p in folder.glob("*.png"))
        if not video.is_file() or video.stat().st_mtime < newest:
            console.print(f"encoding {_show(folder)} as the video {_show(video)}")
            folder_to_video(folder, video, fps=VIDEO_FPS)


def _config_for(name: str, out: Path) -> Path:
    """The run config of ``name``: ``configs/<name>.yaml`` itself when ``out`` is the
    repository's ``demo_out``, else a copy in ``out/configs`` with its paths moved to ``out``."""
    src = CONFIGS / f"{name}.yaml"
    if out.resolve() == (REPO / "demo_out").resolve():
        return src
    text = src.read_text()
    if "../demo_out/" not in text:
        raise SystemExit(f"demo: {src} no longer points at ../demo_out/")
    dst = out / "configs" / src.name
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text(text.replace("../demo_out/", "../"))
    return dst


def _check_config(config: Path, images: Path) -> Path:
    """The run folder of ``config``, after checking its image folders and videos are under
    ``images``."""
    doc = _load(config)
    base = config.parent
    inputs = (c.get("images") or c.get("video") for c in doc["cameras"].values())
    folders = [f for f in inputs if f]
    if doc.get("relpose"):
        folders += list(doc["relpose"]["images"].values())
    for f in folders:
        p = (base / f).resolve()
        if not p.is_relative_to(images.resolve()):
            raise SystemExit(f"demo: {config}: {f} is not under {images}")
    return Path(os.path.normpath(base / doc["output"]))


def _show(path: Path) -> str:
    """``path`` relative to the current folder when it is under it."""
    p = Path(os.path.abspath(path))
    return str(p.relative_to(Path.cwd())) if p.is_relative_to(Path.cwd()) else str(p)


def _image_demo(out: Path, seed: int, frames: int, size: tuple[int, int]) -> None:
    images = out / "images"
    if _images_ok(images, frames, size):
        console.print(f"\nreusing the rendered images in {images}")
    else:
        console.print(
            f"\nrendering the image sample set ({frames} frames, {size[0]}x{size[1]}) into {images}"
        )
        render_sample_set(images, seed=seed, size=size, frames=frames)
    _videos_for(images)
    runs: dict[str, Path] = {}
    for name in RUN_CONFIGS:
        config = _config_for(name, out)
        runs[name] = _check_config(config, images)
        _run("run", _show(config), show=True)

    t_fj = _load(images / "fixed_joint" / "truth.yaml")
    t_gen = _load(images / "general" / "truth.yaml")
    t_ov = _load(images / "overlap" / "truth.yaml")
    table = Table(title="acscal run from rendered images: estimates beside the truth (metres, deg)")
    table.add_column("quantity")
    table.add_column("truth")
    table.add_column("acscal run (refined)")
    table.add_column("error")

    def joint_rows(label: str, truth: dict[str, Any], est_file: Path) -> None:
        est = _load(est_file)["joint"]
        for cam in ("a", "b"):
            key = f"position_in_{cam}"
            t = np.asarray(truth["joint"][key], dtype=float)
            e = np.asarray(est[key], dtype=float)
            err = float(np.linalg.norm(e - t))
            pct = 100.0 * err / float(np.linalg.norm(t))
            table.add_row(f"joint in {cam.upper()}, {label}", _v(t, 4), _v(e, 4),
                          f"{1000 * err:.2f} mm = {pct:.2f}% of |O|")  # fmt: skip

    joint_rows("fixed joint (Alg II)", t_fj, runs["fixed_joint"] / "joint.yaml")
    joint_rows("overlap (Alg I)", t_ov, runs["overlap"] / "joint.yaml")
    rel = _load(runs["fixed_joint"] / "relpose.yaml")["relative_pose"]
    # reference = the run's paired frame 0; the image name's number is the frame index
    ref = round(float(rel["reference_timestamp_a"]))
    T_a_b_true = np.asarray(t_gen["T_a_b"], dtype=float)[ref]
    T_a_b_est = se3.invert_transforms(np.asarray(rel["T_b_a"], dtype=float))
    R_err = T_a_b_true[:3, :3].T @ T_a_b_est[:3, :3]
    ang = float(se3.rotation_angle_deg(R_err))
    rpy_t = se3.rpy_deg_from_matrix(T_a_b_true[:3, :3])
    table.add_row(f"roll/pitch/yaw of R_a_b at frame {ref} (Alg III)", _v(rpy_t, 2),
                  _v(rel["rpy_deg"], 2), f"{ang:.3f} deg (rotation angle)")  # fmt: skip
    t_t = T_a_b_true[:3, 3]
    t_e = np.asarray(rel["translation_b_in_a"], dtype=float)
    table.add_row(f"B's origin in A at frame {ref} (Alg III)", _v(t_t, 4), _v(t_e, 4),
                  f"{1000 * float(np.linalg.norm(t_e - t_t)):.2f} mm")  # fmt: skip
    console.print(table)
    # a Kalibr camchain of the run: intrinsics from the run folder, T_cn_cnm1 at the reference
    camchain = runs["fixed_joint"] / "camchain.yaml"
    _run("export", runs["fixed_joint"] / "relpose.yaml", "--format", "kalibr", "-o", camchain)
    console.print(f"Kalibr camchain: {_show(camchain)}")
    console.print(f"images and truth in {_show(images)}")
    console.print(f"artifacts in {', '.join(_show(r) for r in runs.values())}")
    for r in runs.values():
        console.print(f"report: {_show(r / 'report.html')} (figures in {_show(r)}/report_files)")


if __name__ == "__main__":
    sys.exit(main())
