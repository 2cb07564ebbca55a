"""Incremental structure-from-motion of one camera's image sequence, with pycolmap.

The markerless front end of ``acscal poses --sfm``: SIFT features, sequential or exhaustive
matching (with loop closure from a visual vocabulary), COLMAP's incremental mapper, and the
largest model's camera poses as a trajectory ``T_world_cam`` known up to a similarity.

This module only calls pycolmap (imported inside the functions, so that importing it is
cheap) and returns a typed :class:`SfmResult`; it prints nothing and writes nothing but
COLMAP's work folder that the caller gives it.

Conventions
-----------
- COLMAP's ``image.cam_from_world()`` maps world points into the camera: it is
  ``T_cam_world``; the trajectory holds its inverse ``T_world_cam``.
- Intrinsics here and in :class:`SfmCamera` follow acscal (OpenCV): the centre of the
  top-left pixel is at ``(0, 0)``. COLMAP puts it at ``(0.5, 0.5)``, so its principal point
  is the OpenCV one plus 0.5 px (:func:`colmap_camera`, :func:`camera_from_colmap`).
- acscal's lens models map to COLMAP's: ``pinhole`` (``k1 k2 p1 p2 k3``) to ``OPENCV``
  (``k3 = 0``) or ``FULL_OPENCV`` (``k3 != 0``, ``k4 = k5 = k6 = 0``), ``rational`` to
  ``FULL_OPENCV``, ``fisheye`` (equidistant, ``cv2.fisheye``) to ``OPENCV_FISHEYE``.
  Self-calibration uses ``SIMPLE_RADIAL`` (one focal length, the principal point, ``k1``),
  reported as a pinhole camera.
- The trajectory's world is the first registered image's camera frame, and its unit (an
  "SfM unit") is the mean distance between consecutive registered camera centres: SfM
  fixes neither, so :func:`run_sfm` chooses this gauge.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core import se3
from acs_cli.core.intrinsics import DISTORTION_NAMES, MODELS
from acs_cli.errors import AcsError, DegenerateMotionError, InputError

__all__ = [
    "EXHAUSTIVE_MAX_IMAGES",
    "MATCHING",
    "MIN_FEATURES",
    "MIN_IMAGES",
    "MIN_PARALLAX_DEG",
    "MIN_POINTS",
    "MIN_REGISTERED",
    "SfmCamera",
    "SfmOptions",
    "SfmProgress",
    "SfmResult",
    "camera_from_colmap",
    "colmap_camera",
    "pycolmap_version",
    "run_sfm",
]

#: ``progress(phase, done, total)``: the phase's name and how far it got (images).
SfmProgress = Callable[[str, int, int], None]

#: Matching strategies: ``auto`` is exhaustive up to :data:`EXHAUSTIVE_MAX_IMAGES` images.
MATCHING = ("auto", "sequential", "exhaustive")
#: Largest image set ``auto`` matches exhaustively (every pair).
EXHAUSTIVE_MAX_IMAGES = 40
#: Fewest images a reconstruction is attempted from.
MIN_IMAGES = 3
#: Fewest registered images that make a trajectory.
MIN_REGISTERED = 3
#: Fewest sparse 3-D points a kept model needs.
MIN_POINTS = 20
#: Smallest parallax no rotation explains (deg, :func:`_rotation_only_residual`): below
#: it the camera only rotated (or barely moved) and SfM's translation is noise.
MIN_PARALLAX_DEG = 0.5
#: Fewest SIFT features an image needs to be registered at all (COLMAP's 2D-3D
#: registration needs 30 inliers by default).
MIN_FEATURES = 30
#: Seed of COLMAP's random number generators (RANSAC, sampling): runs are repeatable as
#: far as multi-threading lets them be.
SEED = 0

#: What to record instead, said by every "cannot reconstruct" error.
RECORD_ADVICE = (
    "record the sequence again: a scene with texture (not blank walls, sky, fog or a dark "
    "scene), sharp frames, the camera translating (sideways or forwards, by a few percent "
    "of the scene's depth between frames) and not only rotating in place, with most of "
    "each frame also seen in the next one"
)

# acscal model -> COLMAP model (before the k3 special case of pinhole)
_COLMAP_OF = {"pinhole": "OPENCV", "rational": "FULL_OPENCV", "fisheye": "OPENCV_FISHEYE"}
# COLMAP model -> (acscal model, names of COLMAP's distortion parameters in acscal's order)
_ACSCAL_OF = {
    "OPENCV": "pinhole",
    "FULL_OPENCV": "rational",
    "OPENCV_FISHEYE": "fisheye",
    "SIMPLE_RADIAL": "pinhole",
}
#: The COLMAP model of a self-calibration (one shared camera for the folder).
SELF_CALIBRATION_MODEL = "SIMPLE_RADIAL"
# Most descriptors a vocabulary for loop closure is trained on, and its size range.
_VOCAB_MAX_TRAIN = 100_000
_VOCAB_WORDS = (64, 4096)
_VOCAB_POINTS_PER_WORD = 50


@dataclass(frozen=True)
class SfmCamera:
    """One camera's intrinsics, in acscal's (OpenCV's) convention.

    Attributes
    ----------
    model : {"pinhole", "rational", "fisheye"}
        acscal's lens model; ``distortion`` is in its OpenCV order
        (:data:`acs_cli.core.intrinsics.DISTORTION_NAMES`).
    image_size : tuple of int
        ``(width, height)``, pixels.
    camera_matrix : ndarray, shape (3, 3)
        ``K``, pixels; the centre of the top-left pixel at ``(0, 0)``.
    distortion : ndarray, shape (k,)
        Distortion coefficients (unitless).
    """

    model: str
    image_size: tuple[int, int]
    camera_matrix: np.ndarray
    distortion: np.ndarray


@dataclass(frozen=True)
class SfmOptions:
    """Options of :func:`run_sfm`.

    Attributes
    ----------
    matching : {"auto", "sequential", "exhaustive"}
        ``sequential`` matches each image with the images ``1, 2, 4, ...,
        2**(overlap - 1)`` after it (COLMAP's quadratic overlap: near neighbours for
        tracking, far ones for wide baselines), for video; ``exhaustive`` matches every
        pair; ``auto`` is exhaustive up to :data:`EXHAUSTIVE_MAX_IMAGES` images, else
        sequential.
    overlap : int
        Successors each image is matched with in sequential matching (at power-of-two
        distances: 10 reaches 512 images ahead).
    loop_closure : bool
        Sequential matching also matches each 10th image with the images that look most
        alike (a visual vocabulary): the sequence's return to places it has seen.
    vocab_tree : Path, optional
        A COLMAP (4.x, faiss) vocabulary-tree file for loop closure; without it, a
        vocabulary is trained on the sequence's own features (offline, no download).
    refine_intrinsics : bool
        With a given camera: refine its focal lengths and distortion in the bundle
        adjustments (the principal point stays fixed, as COLMAP advises); else hold it
        fixed. Without a camera intrinsics are always estimated (self-calibration).
    max_image_size : int, optional
        Larger images are downscaled to this many pixels on their longer side for feature
        extraction (coordinates are scaled back); ``None``: full size.
    max_features : int
        Most SIFT features per image.
    threads : int, optional
        Threads of extraction, matching and mapping (``None``: all cores).
    """

    matching: str = "auto"
    overlap: int = 10
    loop_closure: bool = True
    vocab_tree: Path | None = None
    refine_intrinsics: bool = False
    max_image_size: int | None = None
    max_features: int = 8192
    threads: int | None = None

    def __post_init__(self) -> None:
        if self.matching not in MATCHING:
            raise InputError(f"matching must be one of {', '.join(MATCHING)}: {self.matching!r}")
        if self.overlap < 1:
            raise InputError(f"the sequential overlap must be >= 1, got {self.overlap}")
        if self.max_image_size is not None and self.max_image_size < 32:
            raise InputError(f"--max-image-size must be >= 32 px, got {self.max_image_size}")
        if self.max_features < MIN_FEATURES:
            raise InputError(f"max_features must be >= {MIN_FEATURES}, got {self.max_features}")
        if self.threads is not None and self.threads < 1:
            raise InputError(f"threads must be >= 1, got {self.threads}")


@dataclass(frozen=True)
class SfmResult:
    """What :func:`run_sfm` reconstructed (the largest model).

    Attributes
    ----------
    image_names : tuple of str
        Every input image, in the input (sequence) order.
    registered : ndarray of bool, shape (N,)
        Whether each input image has a pose in the kept (largest) model.
    T_world_cam : ndarray, shape (n, 4, 4)
        Pose of each registered image (in input order): camera into world, world = the
        first registered camera's frame, translations in SfM units (mean distance between
        consecutive registered camera centres = 1).
    reprojection_rms_per_image : ndarray, shape (n,)
        RMS reprojection error of each registered image's observations, pixels.
    camera : SfmCamera
        The intrinsics the model ended with (refined or self-calibrated, or as given).
    colmap_model : str
        COLMAP's camera model used (``OPENCV``, ``FULL_OPENCV``, ``OPENCV_FISHEYE``,
        ``SIMPLE_RADIAL``).
    colmap_params : tuple of float
        Its parameters, COLMAP's order and pixel convention.
    intrinsics_source : {"given", "self-calibrated"}
    intrinsics_refined : bool
        Whether the bundle adjustments changed the intrinsics.
    num_points3d : int
        Sparse 3-D points of the kept model.
    mean_track_length : float
        Mean number of images observing each 3-D point.
    reprojection_rms : float
        RMS reprojection error over every observation of the kept model, pixels.
    parallax_deg : float
        The parallax no camera rotation explains, degrees: the largest, over image pairs far
        apart in the sequence, of the median angle between their viewing rays of common
        points after the best rotation between them. About the noise (~0.1 deg) when the
        camera only rotated; the translation is determined when it is large.
    num_models : int
        Models COLMAP made (1 when the sequence did not split).
    model_sizes : tuple of int
        Registered images of each model, the kept one first.
    dropped_images : tuple of str
        Images registered only in the other (smaller) models: they have no pose.
    features_per_image : ndarray of int, shape (N,)
        SIFT features extracted from each input image.
    matching : {"sequential", "exhaustive"}
        The matching done.
    loop_closure : str
        How loop closure went, in words (``"off"``, ``"own vocabulary (... words)"``,
        ``"vocabulary tree FILE"``, or why it was not done).
    loop_pairs : int
        Verified image pairs that only loop closure proposed (beyond the sequential
        window); 0 without loop closure.
    verified_pairs : int
        Image pairs with a verified two-view geometry.
    options : dict
        The options used (for the artifact): this run's :class:`SfmOptions` and COLMAP's
        settings that matter.
    seconds : dict of str to float
        Wall-clock time of each phase (``extraction``, ``vocabulary``, ``matching``,
        ``mapping``, ``total``).
    notes : list of str
        Facts worth a warning (a vocabulary too small, a phase skipped).
    """

    image_names: tuple[str, ...]
    registered: np.ndarray
    T_world_cam: np.ndarray
    reprojection_rms_per_image: np.ndarray
    camera: SfmCamera
    colmap_model: str
    colmap_params: tuple[float, ...]
    intrinsics_source: str
    intrinsics_refined: bool
    num_points3d: int
    mean_track_length: float
    reprojection_rms: float
    parallax_deg: float
    num_models: int
    model_sizes: tuple[int, ...]
    dropped_images: tuple[str, ...]
    features_per_image: np.ndarray
    matching: str
    loop_closure: str
    loop_pairs: int
    verified_pairs: int
    options: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def registered_names(self) -> tuple[str, ...]:
        """The registered images, in input order (one per pose)."""
        return tuple(n for n, r in zip(self.image_names, self.registered, strict=True) if r)

    @property
    def unregistered_names(self) -> tuple[str, ...]:
        """The images without a pose (dropped ones included), in input order."""
        return tuple(n for n, r in zip(self.image_names, self.registered, strict=True) if not r)


def pycolmap_version() -> str:
    """The installed pycolmap's version, with the COLMAP it wraps."""
    pycolmap = _import_pycolmap()
    colmap = str(pycolmap.COLMAP_version)
    if not colmap.startswith("COLMAP"):
        colmap = f"COLMAP {colmap}"
    return f"pycolmap {pycolmap.__version__} ({colmap})"


def _import_pycolmap() -> Any:
    try:
        import pycolmap
    except ImportError as exc:  # an environment without the dependency
        raise AcsError(
            "structure from motion needs pycolmap (COLMAP's Python bindings): "
            "pip install 'pycolmap>=4.2,<5'"
        ) from exc
    return pycolmap


# --------------------------------------------------------------------------------------
# intrinsics: acscal (OpenCV) <-> COLMAP


def colmap_camera(camera: SfmCamera) -> tuple[str, tuple[float, ...]]:
    """COLMAP's camera model and parameters for acscal intrinsics.

    Parameters
    ----------
    camera : SfmCamera
        ``K`` (px, OpenCV convention) and the distortion of ``camera.model``.

    Returns
    -------
    model : str
        ``OPENCV`` (pinhole with ``k3 = 0``), ``FULL_OPENCV`` (rational, or pinhole with
        ``k3 != 0``) or ``OPENCV_FISHEYE`` (fisheye).
    params : tuple of float
        ``fx, fy, cx, cy`` (COLMAP's convention: ``cx, cy`` plus 0.5 px) then the
        distortion in COLMAP's order.

    Raises
    ------
    InputError
        A model COLMAP has no equivalent of, a skewed or malformed ``K``, or a distortion
        of the wrong length.
    """
    if camera.model not in MODELS:
        raise InputError(
            f"camera model {camera.model!r} has no COLMAP equivalent (acscal maps "
            "pinhole, rational and fisheye)"
        )
    K = np.asarray(camera.camera_matrix, dtype=float)
    d = np.asarray(camera.distortion, dtype=float).reshape(-1)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError("the camera matrix must be 3x3 with positive fx, fy")
    if abs(K[0, 1]) > 1e-9 * K[0, 0] or np.abs(K[2] - [0.0, 0.0, 1.0]).max() > 1e-9 or K[1, 0]:
        raise InputError(
            "the camera matrix has a skew or a last row other than [0, 0, 1]: COLMAP's "
            "camera models have no skew"
        )
    n = len(DISTORTION_NAMES[camera.model])
    if d.shape != (n,) or not np.all(np.isfinite(d)):
        raise InputError(f"the {camera.model} model needs {n} finite distortion coefficients")
    base = (K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5)
    if camera.model == "pinhole":
        k1, k2, p1, p2, k3 = d
        if k3 == 0.0:
            return "OPENCV", tuple(float(v) for v in (*base, k1, k2, p1, p2))
        return "FULL_OPENCV", tuple(float(v) for v in (*base, k1, k2, p1, p2, k3, 0, 0, 0))
    return _COLMAP_OF[camera.model], tuple(float(v) for v in (*base, *d))


def camera_from_colmap(
    model: str, params: Sequence[float], image_size: tuple[int, int]
) -> SfmCamera:
    """acscal intrinsics (OpenCV convention) from a COLMAP camera.

    Parameters
    ----------
    model : str
        ``OPENCV``, ``FULL_OPENCV``, ``OPENCV_FISHEYE`` or ``SIMPLE_RADIAL``.
    params : sequence of float
        COLMAP's parameters (principal point in COLMAP's convention).
    image_size : tuple of int
        ``(width, height)``, pixels.

    Returns
    -------
    SfmCamera
        ``OPENCV`` and ``SIMPLE_RADIAL`` as pinhole (``k1 k2 p1 p2 k3``, ``k3 = 0``; for
        ``SIMPLE_RADIAL`` ``fx = fy = f`` and only ``k1``), ``FULL_OPENCV`` as rational,
        ``OPENCV_FISHEYE`` as fisheye.

    Raises
    ------
    ValueError
        Another COLMAP model or a parameter count that does not match (a programming
        error: :func:`run_sfm` only makes these).
    """
    p = [float(v) for v in params]
    counts = {"OPENCV": 8, "FULL_OPENCV": 12, "OPENCV_FISHEYE": 8, "SIMPLE_RADIAL": 4}
    if model not in counts or len(p) != counts[model]:
        raise ValueError(f"unsupported COLMAP camera {model} with {len(p)} parameters")
    if model == "SIMPLE_RADIAL":
        f, cx, cy, k = p
        fx, fy, dist = f, f, [k, 0.0, 0.0, 0.0, 0.0]
    else:
        fx, fy, cx, cy = p[:4]
        dist = p[4:] + ([0.0] if model == "OPENCV" else [])
    K = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
    return SfmCamera(_ACSCAL_OF[model], image_size, K, np.array(dist, dtype=float))


# --------------------------------------------------------------------------------------
# the pipeline


@contextlib.contextmanager
def _colmap_log(workdir: Path) -> Iterator[None]:
    """COLMAP's log (glog) into ``workdir/colmap.log.*``, nothing on the terminal."""
    pycolmap = _import_pycolmap()
    log = pycolmap.logging
    saved = (log.alsologtostderr, log.stderrthreshold, log.logtostderr)
    log.set_log_destination(log.INFO, str(workdir / "colmap.log."))
    for level in (log.WARNING, log.ERROR, log.FATAL):
        log.set_log_destination(level, "")
    log.alsologtostderr, log.stderrthreshold, log.logtostderr = False, 3, False
    try:
        yield
    finally:
        log.set_log_destination(log.INFO, "")  # no log file outside a run (glog's /tmp)
        log.alsologtostderr, log.stderrthreshold, log.logtostderr = saved


@contextlib.contextmanager
def _stderr_into(path: Path) -> Iterator[None]:
    """Send the process's C-level stderr (faiss prints warnings there) into ``path``."""
    try:
        fd = os.dup(2)
    except OSError:  # no stderr to redirect
        yield
        return
    try:
        with open(path, "ab") as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(fd, 2)
    finally:
        os.close(fd)


def _link_images(image_dir: Path, names: Sequence[str], dest: Path) -> list[str]:
    """Links ``dest/000000<suffix>``... to the images, in the input order.

    COLMAP orders a sequence by image name (as strings, so ``img10`` before ``img2``) and
    renumbers images as it likes; numbered links keep the caller's order. A file system
    without symbolic links gets copies.
    """
    dest.mkdir(parents=True, exist_ok=True)
    width = max(6, len(str(len(names))))
    linked = []
    for i, name in enumerate(names):
        src = (image_dir / name).resolve()
        link = dest / f"{i:0{width}d}{Path(name).suffix.lower()}"
        try:
            os.symlink(src, link)
        except OSError:
            try:
                shutil.copyfile(src, link)
            except OSError as exc:
                raise InputError(f"cannot read ({exc.strerror or exc})", path=src) from exc
        linked.append(link.name)
    return linked


def _extract(
    pycolmap: Any,
    database: Path,
    image_path: Path,
    linked: list[str],
    camera: SfmCamera | None,
    options: SfmOptions,
    progress: SfmProgress | None,
) -> None:
    """SIFT features of every image into ``database``, one camera shared by all."""
    reader = pycolmap.ImageReaderOptions()
    if camera is None:
        reader.camera_model = SELF_CALIBRATION_MODEL
    else:
        model, params = colmap_camera(camera)
        reader.camera_model = model
        reader.camera_params = ",".join(repr(v) for v in params)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = options.threads or -1
    extraction.max_image_size = options.max_image_size or -1
    extraction.sift.max_num_features = options.max_features
    n = len(linked)
    # in batches, for progress (each call costs a fraction of a second to start)
    batch = max(25, math.ceil(n / 50))
    for start in range(0, n, batch):
        if progress is not None:
            progress("extracting features", start, n)
        pycolmap.extract_features(
            database,
            image_path,
            image_names=linked[start : start + batch],
            camera_mode=pycolmap.CameraMode.SINGLE,
            reader_options=reader,
            extraction_options=extraction,
        )
        if start == 0:
            db = pycolmap.Database.open(database)
            try:
                cameras = db.read_all_cameras()
            finally:
                db.close()
            if len(cameras) != 1:
                raise RuntimeError(f"COLMAP made {len(cameras)} cameras, expected one")
            reader.existing_camera_id = cameras[0].camera_id
    if progress is not None:
        progress("extracting features", n, n)


def _features(
    pycolmap: Any, database: Path, linked: list[str]
) -> tuple[np.ndarray, dict[int, int]]:
    """Features per linked image (-1: COLMAP could not read it) and ``{image_id: index}``."""
    index_of = {name: i for i, name in enumerate(linked)}
    counts = np.full(len(linked), -1, dtype=np.int64)
    ids: dict[int, int] = {}
    db = pycolmap.Database.open(database)
    try:
        for image in db.read_all_images():
            i = index_of.get(image.name)
            if i is None:
                continue
            ids[int(image.image_id)] = i
            counts[i] = int(db.num_keypoints_for_image(image.image_id))
    finally:
        db.close()
    return counts, ids


def _vocabulary(
    pycolmap: Any, database: Path, out: Path, threads: int | None
) -> tuple[Path | None, str]:
    """Train a visual vocabulary on (a sample of) the sequence's own SIFT descriptors.

    Returns the written index (or None) and how it went, in words.
    """
    rng = np.random.default_rng(SEED)
    db = pycolmap.Database.open(database)
    try:
        images = db.read_all_images()
        per_image = math.ceil(_VOCAB_MAX_TRAIN / max(1, len(images)))
        sample = []
        for image in images:
            d = np.asarray(db.read_descriptors(image.image_id).to_float().data, dtype=np.float32)
            if d.shape[0] > per_image:
                d = d[np.sort(rng.choice(d.shape[0], per_image, replace=False))]
            sample.append(d)
    finally:
        db.close()
    train = np.ascontiguousarray(np.concatenate(sample) if sample else np.zeros((0, 128)))
    words = min(_VOCAB_WORDS[1], train.shape[0] // _VOCAB_POINTS_PER_WORD)
    if words < _VOCAB_WORDS[0]:
        return None, (
            f"not done: {train.shape[0]} SIFT features are too few to train a vocabulary "
            f"({_VOCAB_WORDS[0] * _VOCAB_POINTS_PER_WORD} needed)"
        )
    build = pycolmap.VisualIndex.BuildOptions()
    build.num_visual_words = int(words)
    build.num_iterations = 10
    build.num_rounds = 1
    build.num_threads = threads or -1
    index = pycolmap.VisualIndex.create(128, 64)
    with _stderr_into(out.with_suffix(".log")):  # faiss warns on stderr about small sets
        index.build(
            build, pycolmap.FeatureDescriptorsFloat(pycolmap.FeatureExtractorType.SIFT, train)
        )
    index.write(str(out))
    return out, f"own vocabulary ({index.num_visual_words()} words from {train.shape[0]} features)"


def _sequential_window(i: int, j: int, overlap: int) -> bool:
    """Whether COLMAP's sequential matching with quadratic overlap pairs indices ``i, j``:
    it matches each image with those ``1, 2, 4, ..., 2**(overlap - 1)`` after it."""
    d = abs(i - j)
    return d > 0 and d & (d - 1) == 0 and d.bit_length() - 1 < overlap


def _match(
    pycolmap: Any,
    database: Path,
    workdir: Path,
    n: int,
    ids: dict[int, int],
    options: SfmOptions,
    progress: SfmProgress | None,
) -> tuple[str, str, int, int, float]:
    """Match features; ``(matching, loop_closure, loop_pairs, verified_pairs, vocab_s)``."""
    matching = options.matching
    if matching == "auto":
        matching = "exhaustive" if n <= EXHAUSTIVE_MAX_IMAGES else "sequential"
    threads = options.threads or -1
    match_options = pycolmap.FeatureMatchingOptions()
    match_options.num_threads = threads
    loop = "off"
    vocab_s = 0.0
    if matching == "exhaustive":
        loop = "not needed (every pair matched)"
        phase = "matching every pair"
        if progress is not None:
            progress(phase, 0, n)
        pycolmap.match_exhaustive(database, matching_options=match_options)
    else:
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = options.overlap
        pairing.quadratic_overlap = True
        pairing.num_threads = threads
        if options.loop_closure:
            t0 = time.perf_counter()
            if options.vocab_tree is not None:
                _check_vocab_tree(pycolmap, options.vocab_tree)
                tree: Path | None = options.vocab_tree
                loop = f"vocabulary tree {options.vocab_tree}"
            else:
                if progress is not None:
                    progress("training a vocabulary for loop closure", 0, n)
                tree, loop = _vocabulary(pycolmap, database, workdir / "vocab_tree.bin", threads)
            vocab_s = time.perf_counter() - t0
            if tree is not None:
                pairing.loop_detection = True
                pairing.vocab_tree_path = str(tree)
        phase = "matching neighbouring images"
        if progress is not None:
            progress(phase, 0, n)
        pycolmap.match_sequential(database, matching_options=match_options, pairing_options=pairing)
    db = pycolmap.Database.open(database)
    try:
        pair_ids, geometries = db.read_two_view_geometries()
    finally:
        db.close()
    verified = loops = 0
    for pair, geometry in zip(pair_ids, geometries, strict=True):
        if geometry.inlier_matches.shape[0] < 1:
            continue
        a, b = pair if isinstance(pair, tuple) else pycolmap.pair_id_to_image_pair(pair)
        verified += 1
        i, j = ids.get(int(a)), ids.get(int(b))
        if matching == "sequential" and i is not None and j is not None:
            loops += not _sequential_window(i, j, options.overlap)
    if progress is not None:
        progress(phase, n, n)
    return matching, loop, loops, verified, vocab_s


def _check_vocab_tree(pycolmap: Any, path: Path) -> None:
    if not Path(path).is_file():
        raise InputError("no such vocabulary-tree file", path=path)
    try:
        pycolmap.VisualIndex.read(str(path))
    except Exception as exc:  # pybind11 maps COLMAP's checks to several types
        raise InputError(
            f"not a COLMAP 4 vocabulary tree (faiss format) ({type(exc).__name__}); COLMAP "
            "3.x trees do not load",
            path=path,
        ) from exc


def _mapper_options(
    pycolmap: Any, n: int, camera: SfmCamera | None, options: SfmOptions
) -> tuple[Any, dict[str, Any]]:
    """COLMAP's incremental pipeline options, and what to record of them."""
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = options.threads or -1
    opts.random_seed = SEED
    opts.multiple_models = True
    opts.min_model_size = max(MIN_REGISTERED, min(10, n // 5))
    opts.extract_colors = False
    refine = camera is None or options.refine_intrinsics
    opts.ba_refine_focal_length = refine
    opts.ba_refine_extra_params = refine
    opts.ba_refine_principal_point = False
    opts.mapper.abs_pose_refine_focal_length = refine
    opts.mapper.abs_pose_refine_extra_params = refine
    recorded = {
        "min_model_size": opts.min_model_size,
        "min_num_matches": opts.min_num_matches,
        "refine_focal_length": refine,
        "refine_distortion": refine,
        "refine_principal_point": False,
        "random_seed": SEED,
    }
    return opts, recorded


def _pose_matrix(image: Any) -> np.ndarray:
    """``T_cam_world`` (4x4) of a registered COLMAP image."""
    T = np.eye(4)
    T[:3, :] = np.asarray(image.cam_from_world().matrix(), dtype=float)
    return T


@dataclass(frozen=True)
class _Observations:
    """Per-image reprojection RMS (px, ``(n,)``), the overall RMS (px), and the parallax
    (deg) no rotation explains (:func:`_rotation_only_residual`)."""

    rms_per_image: np.ndarray
    rms: float
    parallax_deg: float


def _wahba(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation ``R`` that best maps unit rays ``a`` onto ``b`` (both (m, 3))."""
    U, _, Vt = np.linalg.svd(b.T @ a)
    return U @ np.diag([1.0, 1.0, float(np.linalg.det(U @ Vt))]) @ Vt


def _rotation_only_residual(
    pids: Sequence[np.ndarray], rays: Sequence[np.ndarray], min_common: int = 10
) -> float:
    """How much of the sequence's image motion no camera rotation explains, in degrees.

    For each image (up to 200, evenly spaced), the image furthest along the sequence that
    shares at least ``min_common`` points with it is paired with it; the best rotation
    between their viewing rays (Wahba's problem) leaves the angles of the parallax. The
    result is the largest over the pairs of the median angle: about the noise (a tenth of a
    degree) when the camera only rotated (or translated too little for the scene's
    depth), whatever translation the reconstruction made up; NaN when no two images share
    ``min_common`` points.

    Parameters
    ----------
    pids : sequence of ndarray of int
        The 3-D point observed by each observation of each image, in sequence order.
    rays : sequence of ndarray, shape (m, 3)
        The observations' unit viewing rays in each camera's frame (from the intrinsics).
    """
    from scipy.sparse import csr_matrix

    n = len(pids)
    if n < 2 or sum(len(p) for p in pids) == 0:
        return float("nan")
    rows = np.concatenate([np.full(len(p), k) for k, p in enumerate(pids)])
    _, cols = np.unique(np.concatenate(pids), return_inverse=True)
    seen = csr_matrix((np.ones(rows.size), (rows, cols.reshape(-1))), shape=(n, cols.max() + 1))
    best = float("nan")
    for i in np.unique(np.linspace(0, n - 2, min(n - 1, 200)).round().astype(int)):
        shared = np.asarray((seen @ seen[i].T).todense()).reshape(-1)
        later = np.flatnonzero(shared[i + 1 :] >= min_common)
        if later.size == 0:
            continue
        j = i + 1 + int(later[-1])
        _, ia, ib = np.intersect1d(pids[i], pids[j], return_indices=True)
        a, b = rays[i][ia], rays[j][ib]
        cos = np.clip(np.einsum("ij,ij->i", a @ _wahba(a, b).T, b), -1.0, 1.0)
        angle = float(np.degrees(np.median(np.arccos(cos))))
        best = angle if not best >= angle else best  # NaN until the first pair
    return best


def _observations(rec: Any, image_ids: Sequence[int]) -> _Observations:
    """Reprojection errors and parallax of the registered images ``image_ids`` (in sequence
    order) of a COLMAP reconstruction."""
    xyz = {int(pid): np.asarray(p.xyz, dtype=float) for pid, p in rec.points3D.items()}
    per_image = []
    total_sq, total_n = 0.0, 0
    pids_of, rays_of = [], []
    for iid in image_ids:
        image = rec.images[iid]
        obs = image.get_observation_points2D()
        if len(obs) == 0:
            per_image.append(float("nan"))
            pids_of.append(np.zeros(0, dtype=np.int64))
            rays_of.append(np.zeros((0, 3)))
            continue
        uv = np.array([p.xy for p in obs], dtype=float)
        pids = np.array([int(p.point3D_id) for p in obs], dtype=np.int64)
        X = np.stack([xyz[int(pid)] for pid in pids])
        T = _pose_matrix(image)  # T_cam_world
        Xc = X @ T[:3, :3].T + T[:3, 3]
        proj = np.asarray(image.camera.img_from_cam(Xc, check_cheirality=False), dtype=float)
        sq = np.sum((proj - uv) ** 2, axis=1)
        sq = sq[np.isfinite(sq)]
        per_image.append(float(np.sqrt(sq.mean())) if sq.size else float("nan"))
        total_sq += float(sq.sum())
        total_n += int(sq.size)
        # the viewing rays of the observations alone (intrinsics, no pose)
        xy = np.asarray(image.camera.cam_from_img(uv), dtype=float)
        ray = np.column_stack([xy, np.ones(len(xy))])
        pids_of.append(pids)
        rays_of.append(ray / np.linalg.norm(ray, axis=1, keepdims=True))
    rms = float(np.sqrt(total_sq / total_n)) if total_n else float("nan")
    return _Observations(
        np.array(per_image, dtype=float), rms, _rotation_only_residual(pids_of, rays_of)
    )


def _gauge(T_cam_world: np.ndarray) -> np.ndarray:
    """``T_world_cam`` with world = the first camera and unit = mean step between centres."""
    T_wc = se3.invert_transforms(T_cam_world)
    T = se3.invert_transforms(T_wc[0])[None] @ T_wc
    steps = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    scale = float(steps.mean()) if steps.size else 0.0
    if scale > 0 and np.isfinite(scale):
        T[:, :3, 3] /= scale
    T[:, 3, :] = [0.0, 0.0, 0.0, 1.0]
    return T


def _no_texture_error(
    names: Sequence[str], counts: np.ndarray, image_dir: Path
) -> DegenerateMotionError:
    poor = [n for n, c in zip(names, counts, strict=True) if c < MIN_FEATURES]
    return DegenerateMotionError(
        f"structure from motion cannot start: {len(poor)} of {len(names)} images have fewer "
        f"than {MIN_FEATURES} SIFT features (blank, dark or textureless frames, e.g. "
        f"{', '.join(poor[:5])}); {RECORD_ADVICE}",
        details={"features_per_image": [int(c) for c in counts]},
        path=image_dir,
    )


def run_sfm(
    image_dir: Path,
    image_names: Sequence[str],
    workdir: Path,
    camera: SfmCamera | None = None,
    options: SfmOptions | None = None,
    progress: SfmProgress | None = None,
) -> SfmResult:
    """Reconstruct one camera's image sequence by incremental structure from motion.

    Parameters
    ----------
    image_dir : Path
        The folder of the images.
    image_names : sequence of str
        The images to use, file names in ``image_dir``, in sequence (time) order; all of
        one size (the caller checks they can be read).
    workdir : Path
        An existing folder for COLMAP's files: ``images/`` (numbered links to the
        images), ``database.db``, ``sparse/<k>/`` (each model), ``vocab_tree.bin`` and
        ``colmap.log.*``. The caller owns it (a temporary folder, or one to keep).
    camera : SfmCamera, optional
        Intrinsics to use (held fixed, or refined with ``options.refine_intrinsics``);
        ``None``: COLMAP self-calibrates one ``SIMPLE_RADIAL`` camera for all images.
    options : SfmOptions, optional
    progress : callable, optional
        ``progress(phase, done, total)``, called as phases start and advance.

    Returns
    -------
    SfmResult
        The largest model's poses (``T_world_cam``, up to a similarity) and quality.

    Raises
    ------
    DegenerateMotionError
        Fewer than :data:`MIN_IMAGES` images, too few with features (blank or textureless
        frames), no verified image pair, fewer than :data:`MIN_REGISTERED` images
        registered or :data:`MIN_POINTS` points triangulated, or a parallax below
        :data:`MIN_PARALLAX_DEG` (a camera that only rotated): the message says what to
        record instead.
    InputError
        A camera COLMAP cannot model, an image COLMAP cannot read, or an unusable
        vocabulary-tree file.
    AcsError
        pycolmap is not installed.
    """
    opts = options or SfmOptions()
    names = list(image_names)
    n = len(names)
    if n < MIN_IMAGES:
        raise DegenerateMotionError(
            f"structure from motion needs at least {MIN_IMAGES} images, got {n}; {RECORD_ADVICE}",
            path=image_dir,
        )
    if camera is not None:
        colmap_camera(camera)  # refuse a camera COLMAP cannot model before any work
    pycolmap = _import_pycolmap()
    workdir = Path(workdir)
    database = workdir / "database.db"
    sparse = workdir / "sparse"
    seconds: dict[str, float] = {}
    t_start = time.perf_counter()
    with _colmap_log(workdir):
        pycolmap.set_random_seed(SEED)
        linked = _link_images(image_dir, names, workdir / "images")
        t0 = time.perf_counter()
        _extract(pycolmap, database, workdir / "images", linked, camera, opts, progress)
        seconds["extraction"] = time.perf_counter() - t0
        counts, ids = _features(pycolmap, database, linked)
        unread = [names[i] for i in np.flatnonzero(counts < 0)]
        if unread:
            raise InputError(
                f"COLMAP could not read {len(unread)} image(s): {', '.join(unread[:5])}",
                path=image_dir / unread[0],
            )
        if int(np.sum(counts >= MIN_FEATURES)) < MIN_IMAGES:
            raise _no_texture_error(names, counts, image_dir)

        t0 = time.perf_counter()
        matching, loop, loop_pairs, verified, vocab_s = _match(
            pycolmap, database, workdir, n, ids, opts, progress
        )
        seconds["vocabulary"] = vocab_s
        seconds["matching"] = time.perf_counter() - t0 - vocab_s
        if verified == 0:
            raise DegenerateMotionError(
                f"structure from motion found no pair of images with a verified geometry "
                f"among {n} images (no common features); {RECORD_ADVICE}",
                path=image_dir,
            )

        t0 = time.perf_counter()
        mapper, mapper_recorded = _mapper_options(pycolmap, n, camera, opts)
        registered_so_far = [0]

        def on_init() -> None:
            registered_so_far[0] = min(n, registered_so_far[0] + 2)
            if progress is not None:
                progress("registering images", registered_so_far[0], n)

        def on_next() -> None:
            registered_so_far[0] = min(n, registered_so_far[0] + 1)
            if progress is not None:
                progress("registering images", registered_so_far[0], n)

        if progress is not None:
            progress("registering images", 0, n)
        sparse.mkdir(parents=True, exist_ok=True)
        models = pycolmap.incremental_mapping(
            database,
            workdir / "images",
            sparse,
            options=mapper,
            initial_image_pair_callback=on_init,
            next_image_callback=on_next,
        )
        seconds["mapping"] = time.perf_counter() - t0
    recs = sorted(
        models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()), reverse=True
    )
    if not recs or recs[0].num_reg_images() < MIN_REGISTERED:
        got = recs[0].num_reg_images() if recs else 0
        raise DegenerateMotionError(
            f"structure from motion registered {got} of {n} images (at least "
            f"{MIN_REGISTERED} needed): no two frames gave a well-conditioned start, e.g. "
            f"a camera that only rotated or barely moved; {RECORD_ADVICE}",
            details={"registered": got, "images": n},
            path=image_dir,
        )
    best = recs[0]
    index_of = {name: i for i, name in enumerate(linked)}
    reg_ids = sorted(
        (index_of[best.images[iid].name], int(iid))
        for iid in best.reg_image_ids()
        if best.images[iid].name in index_of
    )
    registered = np.zeros(n, dtype=bool)
    registered[[i for i, _ in reg_ids]] = True
    in_others = set()
    for rec in recs[1:]:
        in_others |= {index_of[rec.images[iid].name] for iid in rec.reg_image_ids()}
    dropped = tuple(names[i] for i in sorted(in_others) if not registered[i])
    image_ids = [iid for _, iid in reg_ids]
    T_cw = np.stack([_pose_matrix(best.images[iid]) for iid in image_ids])
    if best.num_points3D() < MIN_POINTS:
        raise DegenerateMotionError(
            f"structure from motion registered {len(image_ids)} of {n} images but "
            f"triangulated {best.num_points3D()} points (at least {MIN_POINTS} needed): the "
            f"camera only rotated or barely moved; {RECORD_ADVICE}",
            details={"points3d": int(best.num_points3D())},
            path=image_dir,
        )
    quality = _observations(best, image_ids)
    if np.isnan(quality.parallax_deg):
        raise DegenerateMotionError(
            f"structure from motion registered {len(image_ids)} of {n} images, but no two of "
            f"them share 10 points: the views barely overlap; {RECORD_ADVICE}",
            path=image_dir,
        )
    if quality.parallax_deg < MIN_PARALLAX_DEG:
        raise DegenerateMotionError(
            f"structure from motion cannot determine the camera's translation: a rotation "
            f"alone explains the images to {quality.parallax_deg:.2f} deg (parallax of at "
            f"least {MIN_PARALLAX_DEG} deg needed), so the camera only rotated, or moved too "
            f"little for the scene's depth; {RECORD_ADVICE}",
            details={"parallax_deg": quality.parallax_deg},
            path=image_dir,
        )
    cam = best.cameras[best.images[image_ids[0]].camera_id]
    colmap_model = str(cam.model_name)
    params = tuple(float(v) for v in np.asarray(cam.params, dtype=float))
    size = (int(cam.width), int(cam.height))
    if camera is not None and not opts.refine_intrinsics:
        final = camera
        refined = False
    else:
        final = camera_from_colmap(colmap_model, params, size)
        refined = True
    seconds["total"] = time.perf_counter() - t_start
    recorded = {
        "matching": matching,
        "overlap": opts.overlap if matching == "sequential" else None,
        "loop_closure": opts.loop_closure if matching == "sequential" else False,
        "vocab_tree": None if opts.vocab_tree is None else str(opts.vocab_tree),
        "max_image_size": opts.max_image_size,
        "max_features": opts.max_features,
        "camera_mode": "one camera for all images",
        "mapper": mapper_recorded,
    }
    notes = []
    if matching == "sequential" and opts.loop_closure and loop.startswith("not done"):
        notes.append(f"loop closure {loop}")
    return SfmResult(
        image_names=tuple(names),
        registered=registered,
        T_world_cam=_gauge(T_cw),
        reprojection_rms_per_image=quality.rms_per_image,
        camera=final,
        colmap_model=colmap_model,
        colmap_params=params,
        intrinsics_source="self-calibrated" if camera is None else "given",
        intrinsics_refined=refined,
        num_points3d=int(best.num_points3D()),
        mean_track_length=float(best.compute_mean_track_length()),
        reprojection_rms=quality.rms,
        parallax_deg=quality.parallax_deg,
        num_models=len(recs),
        model_sizes=tuple(int(r.num_reg_images()) for r in recs),
        dropped_images=dropped,
        features_per_image=counts,
        matching=matching,
        loop_closure=loop,
        loop_pairs=int(loop_pairs),
        verified_pairs=int(verified),
        options=recorded,
        seconds=seconds,
        notes=notes,
    )
