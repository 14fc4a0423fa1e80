"""Several pairs from one recording: one pair per image, each with the scans around it.

A multi-pair calibration is recorded in one go; these forms cut it into pairs
(:meth:`nbcalib.preprocess.inputs.InputSpec.gather` picks the form):

- **a folder of frames** (:func:`gather_frames`, ``--frames DIR``): subfolders that each hold
  one point cloud and one image (``DIR/0000000000/velodyne.bin`` + ``image_02.png``), in natural
  name order; or the KITTI raw layout, ``DIR/velodyne_points/data/*.bin`` +
  ``DIR/image_02/data/*.png`` (or the only ``image_0N`` folder), frames matched by file stem;
- **a scan sequence and several images** (:func:`gather_image_sequence`, ``--images``): image
  ``i`` was taken during scan ``i``, or at its ``--image-times`` against the scans' times
  (``--scan-times``, else scan ``k`` begins at ``k / frame_rate``);
- **bags with an image selection** (:func:`gather_bag_pairs`, ``--every N``, ``--pair-count N``
  or ``--image-times``): the header stamps of the images against those of the scans.

``--every N`` (every Nth image) and ``--pair-count N`` (N images spread evenly, the first and
the last among them) choose the images of every form. Each chosen image is *anchored* in the
scan taken while it was taken, at a fraction of that scan's sweep (0 = its first point, 1 = its
last): from the times where there are some (a scan's stamp is the time of its first point, its
sweep lasts as long as its per-point times span, else ``1 / frame_rate``), else
:attr:`~nbcalib.preprocess.config.PreprocessConfig.image_scan_fraction` (0.5 by default: KITTI
and every camera triggered when a spinning LiDAR faces forward). The pair accumulates the
:attr:`~nbcalib.preprocess.config.PreprocessConfig.neighbors` scans around its anchor (its own
among them; shifted at the ends of the recording, and clipped with a warning when the recording
has fewer), and :func:`nbcalib.preprocess.prepare.prepare_pair` expresses the dense cloud in the
LiDAR frame at the image's time (:meth:`~nbcalib.preprocess.accumulate.DenseCloud.pose_at`).

Pair names are stable and unique: the frame's folder name or file stem, the image's file stem,
or the bag's name and the image's index on its topic (``run1_000012``).
"""

from __future__ import annotations

import calendar
import logging
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.preprocess.config import PreprocessConfig

__all__ = [
    "gather_bag_pairs",
    "gather_frames",
    "gather_image_sequence",
    "parse_times",
    "scan_window",
    "select_images",
]

log = logging.getLogger("nbcalib.preprocess")

#: KITTI raw: the scans' folder, and the camera whose images are used when there are several
KITTI_SCANS = Path("velodyne_points") / "data"
KITTI_CAMERA = "image_02"

_KITTI_STAMP = re.compile(r"^(\d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2})(?:\.(\d+))?$")


@dataclass(frozen=True)
class _Shot:
    """One chosen image: where it is among the recording's images and scans."""

    index: int  # among the recording's images
    name: str  # the pair's name
    scan: int  # the recording's scan taken while the image was taken
    fraction: float | None  # its time as a fraction of that sweep; None: from ``time``
    time: float | None = None  # seconds, on the scans' clock (``begins``)


# ---------------------------------------------------------------------------------------------
# Choosing images and scans


def select_images(count: int, *, every: int | None = None, pair_count: int | None = None):
    """Indices of the images to make pairs at, among ``count`` (module docstring).

    ``every``: 0, N, 2N...; ``pair_count``: N indices spread evenly from the first to the last
    (one: the first); neither: all.

    Raises
    ------
    InputError
        ``pair_count`` above ``count``.
    """
    if every is not None:
        return list(range(0, count, every))
    if pair_count is not None:
        if pair_count > count:
            raise InputError(
                f"inputs.pair_count {pair_count} asks more pairs than the {count} images"
            )
        if pair_count == 1:
            return [0]
        step = (count - 1) / (pair_count - 1)
        return [math.floor(k * step + 0.5) for k in range(pair_count)]
    return list(range(count))


def scan_window(scan: int, neighbors: int, count: int) -> range:
    """The ``neighbors`` consecutive scans around ``scan`` among ``count`` (its own included).

    Centred (one more after than before for an even number), shifted at the ends of the
    recording, and clipped to ``count`` scans.
    """
    size = min(neighbors, count)
    start = max(0, min(scan - (size - 1) // 2, count - size))
    return range(start, start + size)


def _anchor(begins: np.ndarray, time: float) -> int:
    """The scan whose sweep holds ``time``: the last to begin at or before it (else the first)."""
    return max(int(np.searchsorted(begins, time, side="right")) - 1, 0)


def _duration(cloud, frame_rate: float) -> float:
    """How long a scan's sweep lasts: its per-point times' span, else ``1 / frame_rate``."""
    times = getattr(cloud, "times", None)
    if times is not None and len(times):
        span = float(np.max(times) - np.min(times))
        if span > 0:
            return span
    return 1.0 / frame_rate


# ---------------------------------------------------------------------------------------------
# Times


def _stamp_seconds(text: str) -> float | None:
    """``2011-09-26 13:02:25.964389445`` (KITTI's timestamps.txt, UTC) as epoch seconds."""
    match = _KITTI_STAMP.match(text)
    if match is None:
        return None
    whole = calendar.timegm(datetime.strptime(match.group(1), "%Y-%m-%d %H:%M:%S").timetuple())
    digits = match.group(2) or "0"
    return whole + int(digits) / 10 ** len(digits)


def parse_times(text: str, option: str) -> np.ndarray:
    """Seconds from ``a,b,c`` or from a file of one time per line.

    A file's lines are numbers (seconds) or KITTI stamps (``2011-09-26 13:02:25.964389445``);
    blank lines and lines starting with ``#`` are skipped.

    Raises
    ------
    InputError
        Neither numbers nor a readable file, a line that is no time (names the file and the
        line), or no time at all.
    """
    text = str(text).strip()
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = None
    if values is None:
        path = Path(text)
        if not path.is_file():
            raise InputError(
                f"{option} must be comma-separated seconds or a file of times, got {text!r}"
            )
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read the times: {exc}", path) from None
        values = []
        for number, line in enumerate(lines, start=1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            try:
                values.append(float(line))
            except ValueError:
                seconds = _stamp_seconds(line)
                if seconds is None:
                    raise InputError(
                        f"line {number} is not a time (seconds or YYYY-MM-DD HH:MM:SS.f): "
                        f"{line[:40]!r}",
                        path,
                    ) from None
                values.append(seconds)
    times = np.asarray(values, dtype=np.float64)
    if times.size == 0:
        raise InputError(f"{option}: no time given")
    if not np.isfinite(times).all():
        raise InputError(f"{option}: the times must be finite")
    return times


# ---------------------------------------------------------------------------------------------
# Pairs


def _neighbors(config: PreprocessConfig, count: int, where) -> int:
    """The scans per pair, with a warning when the recording has fewer."""
    wanted = config.neighbors
    if config.max_scans is not None:
        wanted = min(wanted, config.max_scans)
    if wanted > count:
        log.warning(
            "%s: %d scans per pair asked (neighbors) but the recording has %d: each pair "
            "accumulates %d",
            where,
            wanted,
            count,
            count,
        )
    return wanted


def _make_pairs(
    shots: Sequence[_Shot],
    count: int,
    load_scans: Callable[[list[int]], dict],
    load_images: Callable[[list[int]], dict],
    config: PreprocessConfig,
    where,
    *,
    begins: np.ndarray | None = None,
    camera=None,
    topics: dict | None = None,
):
    """One :class:`~nbcalib.preprocess.inputs.PairInput` per shot, with its window of scans.

    ``load_scans`` maps scan indices to point clouds, ``load_images`` image indices to
    ``(image, source)``; every scan is read once (pairs that share it share the object).
    """
    from nbcalib.preprocess.sources import PairInput

    if not shots:
        raise InputError("no image to make a pair at", where)
    neighbors = _neighbors(config, count, where)
    windows = [scan_window(shot.scan, neighbors, count) for shot in shots]
    scans = load_scans(sorted(set().union(*windows)))
    images = load_images([shot.index for shot in shots])
    period = 1.0 / config.frame_rate
    pairs = []
    for shot, window in zip(shots, windows):
        fraction, time = shot.fraction, shot.time
        if fraction is None:
            begin = float(begins[shot.scan])
            duration = _duration(scans[shot.scan], config.frame_rate)
            offset = time - begin
            if offset < -period or offset > duration + period:
                log.warning(
                    "%s: image %s is %.3f s away from the sweep of its nearest scan (%d)",
                    where,
                    shot.name,
                    -offset if offset < 0 else offset - duration,
                    shot.scan,
                )
            fraction = float(np.clip(offset / duration, 0.0, 1.0))
        image, source = images[shot.index]
        info = {
            "first_scan": window.start,
            "image_scan": shot.scan,
            "image_fraction": fraction,
        }
        if time is not None:
            info["image_time"] = time
        pairs.append(
            PairInput(
                shot.name,
                [scans[k] for k in window],
                image,
                source,
                camera,
                dict(topics or {}),
                image_scan=shot.scan - window.start,
                image_fraction=fraction,
                info=info,
            )
        )
    return pairs


def _file_loaders(scan_paths: Sequence[Path], image_paths: Sequence[Path], config):
    from nbcalib.io.image import read_image
    from nbcalib.preprocess.sources import read_scan

    def load_scans(indices):
        channel = config.intensity_channel
        return {k: read_scan(scan_paths[k], intensity_channel=channel) for k in indices}

    def load_images(indices):
        out = {}
        for k in indices:
            path = Path(image_paths[k])
            if not path.is_file():
                raise InputError("image not found", path)
            out[k] = (read_image(path, grey=True), str(path))
        return out

    return load_scans, load_images


def _natural(name: str):
    """Sort key: digits as numbers (``frame_2`` before ``frame_10``)."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def _of_kind(folder: Path, suffixes) -> list[Path]:
    return sorted(
        (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes),
        key=lambda p: _natural(p.name),
    )


# ---------------------------------------------------------------------------------------------
# The forms


def gather_frames(folder, config: PreprocessConfig, *, every=None, pair_count=None):
    """A folder of frames (module docstring): one pair per chosen frame.

    Raises
    ------
    InputError
        No such folder, no frame in it, or a frame without its image or its point cloud (the
        message names the frame), a frame with several of either, or KITTI timestamps that do
        not fit the files.
    """
    from nbcalib.preprocess.sources import CLOUD_SUFFIXES, IMAGE_SUFFIXES

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("no such folder (inputs.frames: a folder of frame folders)", folder)
    if (folder / KITTI_SCANS).is_dir():
        names, scans, images, fractions = _kitti_raw_frames(folder, config)
    else:
        names, scans, images = [], [], []
        subfolders = sorted(
            (p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")),
            key=lambda p: _natural(p.name),
        )
        for sub in subfolders:
            clouds, pictures = _of_kind(sub, CLOUD_SUFFIXES), _of_kind(sub, IMAGE_SUFFIXES)
            if not clouds and not pictures:
                continue  # not a frame (calib/, notes...)
            if not pictures:
                raise InputError("frame has a point cloud but no image (.png, .jpg...)", sub)
            if not clouds:
                raise InputError(
                    f"frame has an image but no point cloud ({', '.join(CLOUD_SUFFIXES)})", sub
                )
            for what, found in (("point clouds", clouds), ("images", pictures)):
                if len(found) > 1:
                    listed = ", ".join(p.name for p in found)
                    raise InputError(f"frame holds {len(found)} {what} ({listed}); one each", sub)
            names.append(sub.name)
            scans.append(clouds[0])
            images.append(pictures[0])
        if not names:
            raise InputError(
                "no frame in the folder: expected subfolders each holding one point cloud and "
                "one image, or the KITTI raw layout (velodyne_points/data, image_02/data)",
                folder,
            )
        fractions = [config.image_scan_fraction] * len(names)
    chosen = select_images(len(names), every=every, pair_count=pair_count)
    shots = [_Shot(k, names[k], k, fractions[k]) for k in chosen]
    load_scans, load_images = _file_loaders(scans, images, config)
    return _make_pairs(shots, len(scans), load_scans, load_images, config, folder)


def _kitti_raw_frames(folder: Path, config: PreprocessConfig):
    """(names, scans, images, fractions) of the KITTI raw layout, matched by file stem.

    With ``velodyne_points/timestamps_start.txt``, ``timestamps_end.txt`` and the camera's
    ``timestamps.txt`` (line ``i`` for the file named ``i``), each image's fraction of its sweep
    comes from them; else it is ``image_scan_fraction``.
    """
    from nbcalib.preprocess.sources import CLOUD_SUFFIXES, IMAGE_SUFFIXES

    cameras = sorted(p for p in folder.glob("image_0*") if (p / "data").is_dir())
    if not cameras:
        raise InputError("KITTI raw layout without an image_0N/data folder", folder)
    camera = next((p for p in cameras if p.name == KITTI_CAMERA), None)
    if camera is None:
        if len(cameras) > 1:
            listed = ", ".join(p.name for p in cameras)
            raise InputError(f"several cameras ({listed}) and no {KITTI_CAMERA}", folder)
        camera = cameras[0]
    scans = {p.stem: p for p in _of_kind(folder / KITTI_SCANS, CLOUD_SUFFIXES)}
    images = {p.stem: p for p in _of_kind(camera / "data", IMAGE_SUFFIXES)}
    for stem in scans.keys() - images.keys():
        raise InputError(f"scan without an image in {camera / 'data'}", scans[stem])
    for stem in images.keys() - scans.keys():
        raise InputError(f"image without a scan in {folder / KITTI_SCANS}", images[stem])
    names = sorted(scans, key=_natural)
    if not names:
        raise InputError("no scan in the folder", folder / KITTI_SCANS)
    fractions = [config.image_scan_fraction] * len(names)
    stamp_files = (
        folder / "velodyne_points" / "timestamps_start.txt",
        folder / "velodyne_points" / "timestamps_end.txt",
        camera / "timestamps.txt",
    )
    if all(p.is_file() for p in stamp_files):
        starts, ends, shots = (parse_times(str(p), p.name) for p in stamp_files)
        for k, name in enumerate(names):
            line = int(name) if name.isdigit() else -1
            for path, times in zip(stamp_files, (starts, ends, shots)):
                if not 0 <= line < times.size:
                    raise InputError(f"no line for the frame named {name}", path)
            sweep = ends[line] - starts[line]
            if sweep > 0:
                fractions[k] = float(np.clip((shots[line] - starts[line]) / sweep, 0.0, 1.0))
    return names, [scans[n] for n in names], [images[n] for n in names], fractions


def gather_image_sequence(
    cloud_paths,
    image_paths,
    config: PreprocessConfig,
    *,
    image_times=None,
    scan_times=None,
    every=None,
    pair_count=None,
):
    """Scans in time order and several images (module docstring): one pair per chosen image.

    Raises
    ------
    InputError
        No scan, more images than scans without times, times that do not match the files in
        number or are not in time order, or two images of the same name.
    """
    scan_paths, image_paths = [Path(p) for p in cloud_paths], [Path(p) for p in image_paths]
    if not scan_paths:
        raise InputError(
            "inputs.images needs the point clouds (INPUT... or inputs.points), in time order"
        )
    stems = [p.stem for p in image_paths]
    if len(set(stems)) != len(stems):
        twice = sorted({s for s in stems if stems.count(s) > 1})
        raise InputError(f"two images have the same name {twice[0]!r}: pairs are named by it")
    n_scans = len(scan_paths)
    begins = None
    if scan_times is not None:
        begins = parse_times(scan_times, "inputs.scan_times")
        if begins.size != n_scans:
            raise InputError(f"inputs.scan_times gives {begins.size} times for {n_scans} scans")
        if np.any(np.diff(begins) <= 0):
            raise InputError("inputs.scan_times must increase (the scans in time order)")
    if image_times is None:
        if len(image_paths) > n_scans:
            raise InputError(
                f"{len(image_paths)} images but {n_scans} scans: image i goes with scan i; "
                "give inputs.image_times (and inputs.scan_times) to place them"
            )
        shots = [_Shot(k, stems[k], k, config.image_scan_fraction) for k in range(len(stems))]
    else:
        times = parse_times(image_times, "inputs.image_times")
        if times.size != len(image_paths):
            raise InputError(
                f"inputs.image_times gives {times.size} times for {len(image_paths)} images"
            )
        if begins is None:
            begins = np.arange(n_scans) / config.frame_rate
        shots = [
            _Shot(k, stems[k], _anchor(begins, t), None, float(t)) for k, t in enumerate(times)
        ]
    shots = [shots[k] for k in select_images(len(shots), every=every, pair_count=pair_count)]
    load_scans, load_images = _file_loaders(scan_paths, image_paths, config)
    where = scan_paths[0].parent
    return _make_pairs(shots, n_scans, load_scans, load_images, config, where, begins=begins)


def gather_bag_pairs(
    path, config: PreprocessConfig, *, image_times=None, every=None, pair_count=None
):
    """A bag cut into one pair per chosen image (module docstring).

    Only the scans and images the pairs use are decoded: the header stamps of every message are
    read first.

    Raises
    ------
    InputError
        Missing topics or messages, a given time with no image near it, or two times that pick
        the same image.
    """
    from nbcalib.io.bag import open_bag
    from nbcalib.preprocess.sources import bag_name, bag_topics

    path = Path(path)
    stem = bag_name(path)
    stem = stem[: -len(".bag")] if stem.lower().endswith(".bag") else stem
    with open_bag(path) as bag:
        points_topic, image_topic, info_topic, camera = bag_topics(bag, config, path)
        scan_stamps = np.asarray(bag.stamps(points_topic), dtype=np.int64)
        image_stamps = np.asarray(bag.stamps(image_topic), dtype=np.int64)
        if scan_stamps.size == 0:
            raise InputError(f"point cloud topic {points_topic} has no messages", path=path)
        if image_stamps.size == 0:
            raise InputError(f"image topic {image_topic} has no messages", path=path)
        if np.any(np.diff(scan_stamps) < 0):
            raise InputError(f"the stamps on {points_topic} are not in time order", path=path)
        zero = int(scan_stamps[0])
        begins = (scan_stamps - zero) / 1e9
        seconds = (image_stamps - zero) / 1e9
        if image_times is not None:
            chosen = _nearest_images(
                parse_times(image_times, "inputs.image_times"), image_stamps, path
            )
        else:
            last = begins[-1] + 1.0 / config.frame_rate
            inside = np.flatnonzero((seconds >= begins[0]) & (seconds <= last)).tolist()
            if not inside:
                raise InputError(
                    f"no image on {image_topic} was taken while the LiDAR recorded", path=path
                )
            chosen = [
                inside[k] for k in select_images(len(inside), every=every, pair_count=pair_count)
            ]
        shots = [
            _Shot(k, f"{stem}_{k:06d}", _anchor(begins, seconds[k]), None, float(seconds[k]))
            for k in chosen
        ]

        def load_scans(indices):
            clouds = bag.pointclouds(
                points_topic, intensity_channel=config.intensity_channel, only=set(indices)
            )
            return {k: cloud for k, (_, cloud) in zip(indices, clouds)}

        def load_images(indices):
            found = bag.images(image_topic, grey=True, only=set(indices))
            return {
                k: (image, f"{path} {image_topic} #{k}")
                for k, (_, image) in zip(sorted(indices), found)
            }

        topics = {
            "points_topic": points_topic,
            "image_topic": image_topic,
            "camera_info_topic": info_topic,
        }
        return _make_pairs(
            shots,
            scan_stamps.size,
            load_scans,
            load_images,
            config,
            path,
            begins=begins,
            camera=camera,
            topics=topics,
        )


def _nearest_images(times: np.ndarray, stamps: np.ndarray, path) -> list[int]:
    """The image nearest each given time (header stamps, seconds), within one image period."""
    seconds = stamps / 1e9
    period = float(np.median(np.diff(seconds))) if seconds.size > 1 else 1.0
    chosen: dict[int, float] = {}
    for t in times:
        k = int(np.argmin(np.abs(seconds - t)))
        if abs(seconds[k] - t) > period:
            raise InputError(
                f"no image within {period:.3f} s of {t:.6f} (the images span "
                f"{seconds[0]:.6f} .. {seconds[-1]:.6f}; inputs.image_times are header stamps in "
                "seconds)",
                path,
            )
        if k in chosen:
            raise InputError(
                f"inputs.image_times {chosen[k]:.6f} and {t:.6f} pick the same image",
                path,
            )
        chosen[k] = float(t)
    return sorted(chosen)
