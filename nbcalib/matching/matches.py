"""Keypoint matches between a camera image and a LiDAR image, and the ``<name>_matches.json`` file.

The file keeps the reference toolbox's format (reference_toolbox.md section 1.3), so either
tool's ``initial_guess`` reads the other's matches::

    {
      "kpts0": [x0, y0, x1, y1, ...],   camera keypoints, pixels
      "kpts1": [x0, y0, ...],           LiDAR-image keypoints, pixels (nbcalib: whole pixels)
      "matches": [j0, j1, ...],         one per camera keypoint: index into kpts1, or -1
      "confidence": [c0, c1, ...],      one per camera keypoint
      "nbcalib": {"matcher": "..."}     nbcalib's addition (the reference ignores it)
    }

Pixel coordinates follow docs/conventions.md section 6 (centres at integers), in the original,
unrotated images.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._files import write_text_atomic

__all__ = ["Matches", "read_matches_json", "write_matches_json"]


@dataclass(frozen=True)
class Matches:
    """Keypoints of a camera image and a LiDAR image and the matches between them.

    Attributes
    ----------
    kpts_camera : ndarray of shape (M, 2), float64
        Camera-image keypoints ``(u, v)``, pixels.
    kpts_lidar : ndarray of shape (K, 2), float64
        LiDAR-image keypoints ``(u, v)``, pixels.
    matches : ndarray of shape (M,), int64
        For each camera keypoint the index of its LiDAR keypoint, or -1.
    confidence : ndarray of shape (M,), float64
        Match score of each camera keypoint (matcher-specific, higher is better; 0 when
        unmatched, or a score below the match threshold).
    matcher : str
        The matcher that made them (``aliked-lightglue``, ``sift``, ...).
    info : dict
        Free-form details (options used, timings), written under ``nbcalib``.
    """

    kpts_camera: np.ndarray
    kpts_lidar: np.ndarray
    matches: np.ndarray
    confidence: np.ndarray
    matcher: str = ""
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        kc = np.ascontiguousarray(self.kpts_camera, dtype=np.float64).reshape(-1, 2)
        kl = np.ascontiguousarray(self.kpts_lidar, dtype=np.float64).reshape(-1, 2)
        m = np.ascontiguousarray(self.matches, dtype=np.int64).reshape(-1)
        c = np.ascontiguousarray(self.confidence, dtype=np.float64).reshape(-1)
        if m.shape[0] != kc.shape[0] or c.shape[0] != kc.shape[0]:
            raise ValueError(
                f"matches ({m.shape[0]}) and confidence ({c.shape[0]}) need one entry per "
                f"camera keypoint ({kc.shape[0]})"
            )
        if np.any(m < -1) or np.any(m >= kl.shape[0]):
            raise ValueError(f"matches must be -1 or an index into {kl.shape[0]} LiDAR keypoints")
        if not (np.all(np.isfinite(kc)) and np.all(np.isfinite(kl)) and np.all(np.isfinite(c))):
            raise ValueError("keypoints and confidences must be finite")
        object.__setattr__(self, "kpts_camera", kc)
        object.__setattr__(self, "kpts_lidar", kl)
        object.__setattr__(self, "matches", m)
        object.__setattr__(self, "confidence", c)

    @property
    def num_matches(self) -> int:
        """Number of matched camera keypoints."""
        return int(np.count_nonzero(self.matches >= 0))

    def matched(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The matched pairs.

        Returns
        -------
        uv_camera : ndarray of shape (S, 2), float64
        uv_lidar : ndarray of shape (S, 2), float64
        confidence : ndarray of shape (S,), float64
        """
        valid = self.matches >= 0
        return (
            self.kpts_camera[valid],
            self.kpts_lidar[self.matches[valid]],
            self.confidence[valid],
        )


def _numbers(kpts: np.ndarray) -> list:
    """Flat keypoint coordinates; whole pixels as JSON integers (the reference reads ints)."""
    return [int(x) if x.is_integer() else float(x) for x in kpts.reshape(-1).tolist()]


def write_matches_json(path: str | os.PathLike, matches: Matches) -> None:
    """Write ``<name>_matches.json`` (reference format, module docstring), atomically.

    Whole-pixel keypoints (nbcalib's LiDAR keypoints, :func:`~nbcalib.matching.find.
    reference_matches`) are written as integers.
    """
    path = Path(path)
    doc = {
        "kpts0": _numbers(matches.kpts_camera),
        "kpts1": _numbers(matches.kpts_lidar),
        "matches": [int(x) for x in matches.matches],
        "confidence": [float(x) for x in matches.confidence],
        "nbcalib": {"matcher": matches.matcher, **matches.info},
    }
    write_text_atomic(path, json.dumps(doc, indent=2, sort_keys=True) + "\n")


def read_matches_json(path: str | os.PathLike) -> Matches:
    """Read a ``<name>_matches.json`` written by nbcalib or by the reference's script.

    Raises
    ------
    InputError
        Missing or unreadable file, or arrays of inconsistent lengths; names the file.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError("matches file not found (run 'nbcalib find-matches')", path) from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"not a readable JSON file ({exc})", path) from None
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object with kpts0, kpts1, matches, confidence", path)
    missing = [k for k in ("kpts0", "kpts1", "matches", "confidence") if k not in doc]
    if missing:
        raise InputError(f"missing keys {missing}", path)
    try:
        kpts0 = np.asarray(doc["kpts0"], dtype=np.float64)
        kpts1 = np.asarray(doc["kpts1"], dtype=np.float64)
        raw = np.asarray(doc["matches"], dtype=np.float64)
        confidence = np.asarray(doc["confidence"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"non-numeric entries ({exc})", path) from None
    if kpts0.ndim != 1 or kpts0.size % 2 or kpts1.ndim != 1 or kpts1.size % 2:
        raise InputError("kpts0 and kpts1 must be flat lists [x0, y0, x1, y1, ...]", path)
    if raw.ndim != 1 or not np.all(raw == np.round(raw)):
        raise InputError("matches must be a flat list of integers", path)
    extra = doc.get("nbcalib") if isinstance(doc.get("nbcalib"), dict) else {}
    info = {k: v for k, v in extra.items() if k != "matcher"}
    try:
        return Matches(
            kpts0.reshape(-1, 2),
            kpts1.reshape(-1, 2),
            raw.astype(np.int64),
            confidence,
            matcher=str(extra.get("matcher", "")),
            info=info,
        )
    except ValueError as exc:
        raise InputError(str(exc), path) from None
