"""Write synthetic pairs to disk in the formats users have (``nbcalib synth``).

Layout of ``OUT`` (``name`` = ``pair_000``, ``pair_001``, ...)::

    OUT/camera.yaml                 the camera (nbcalib camera file)
    OUT/<name>.png                  files: the image, taken at the start of the first scan
    OUT/<name>.pcd                  files: every scan of the pair; t = seconds since the image
    OUT/<name>_scans/scan_0000.pcd  files, moving rig only: one PCD per scan, t = seconds since
                                    that scan's start (for motion-compensated integration)
    OUT/<name>.bag                  bag1: ROS 1 bag          } one bag per pair: tf_static,
    OUT/<name>/                     bag2 / mcap: ROS 2 bag   } camera_info, image, then scans
    OUT/ground_truth.json           written last: a run that crashed has none

A camera ring (``RigConfig.cameras``, :func:`~nbcalib.synthetic.rig.generate_ring`) writes the
scans once and an image per camera ``cam0``, ``cam1``, ...: ``OUT/<camera>/<name>.png`` and
``OUT/<camera>/camera.yaml`` with ``OUT/<name>.pcd`` (files), or in each bag
``/<camera>/image`` and ``/<camera>/camera_info`` (:func:`ring_topics`) and a ``/tf_static``
from ``lidar`` to each camera's frame ``<camera>``. ``ground_truth.json`` keeps the first
camera's extrinsic at the top (so a one-camera tool judges that camera) and every camera's
under ``cameras``.

PCD and PointCloud2 fields: ``x, y, z`` float32 (metres, LiDAR frame at the point's time),
``intensity`` float32 (0-255), ``t`` float32 (seconds), ``ring`` uint16. Bags hold the topics of
:data:`TOPICS` in the frames :data:`FRAMES`; the image and the first scan share the stamp
``BASE_STAMP_NS + 1000 s * pair``.

With ``"motion"`` in ``RigConfig.without`` each pair's points are written as one cloud already
deskewed with the true trajectory (:meth:`~nbcalib.synthetic.rig.SyntheticSequence.output_scans`):
``<name>.pcd`` in the LiDAR frame at the image time with ``t = 0`` and no ``<name>_scans/``
folder, or one ``/points`` message at the image's stamp in a bag. ``ground_truth.json`` records
the switches as ``"without"`` (a list, empty by default) next to ``"modality_gap"``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from nbcalib.io._files import write_text_atomic
from nbcalib.progress import Progress
from nbcalib.synthetic.intrinsics import GivenIntrinsics
from nbcalib.synthetic.lidar import LidarScan
from nbcalib.synthetic.rig import (
    RigConfig,
    SyntheticSequence,
    generate_ring,
    generate_sequence,
    ring_cameras,
)
from nbcalib.transforms import invert_T, pose_to_xyz_quat

__all__ = [
    "BASE_STAMP_NS",
    "FORMATS",
    "FRAMES",
    "TOPICS",
    "export_dataset",
    "ground_truth_dict",
    "pair_name",
    "ring_topics",
    "scan_fields",
    "write_sequence_bag",
    "write_sequence_files",
]

FORMATS = ("files", "bag1", "bag2", "mcap")
#: Topics of the bags
TOPICS = {
    "points": "/points",
    "image": "/image",
    "camera_info": "/camera_info",
}
#: Frame ids of the bags: the LiDAR body frame and the camera optical frame
FRAMES = {"lidar": "lidar", "camera": "camera"}
#: Stamp of the first pair's image and first scan (2023-11-14 22:13:20 UTC), nanoseconds
BASE_STAMP_NS = 1_700_000_000 * 1_000_000_000


def pair_name(pair: int) -> str:
    """File stem of a pair: ``pair_000``."""
    return f"pair_{pair:03d}"


def scan_fields(scan: LidarScan, *, time_offset: float = 0.0) -> dict[str, np.ndarray]:
    """The point fields of a scan as written: x, y, z, intensity, t (+ ``time_offset``), ring."""
    return {
        "x": scan.points[:, 0].astype(np.float32),
        "y": scan.points[:, 1].astype(np.float32),
        "z": scan.points[:, 2].astype(np.float32),
        "intensity": scan.intensities.astype(np.float32),
        "t": (scan.times + time_offset).astype(np.float32),
        "ring": scan.rings.astype(np.uint16),
    }


def _moving(sequence: SyntheticSequence) -> bool:
    """Whether the written scans need deskewing (a moving rig, not motion-compensated)."""
    return (
        sequence.motion.kind != "static"
        and len(sequence.scans) > 1
        and "motion" not in sequence.config.without
    )


def ring_topics(camera: str) -> dict[str, str]:
    """The image and camera info topics of a ring's camera ``camera`` (``cam0``...)."""
    return {"image": f"/{camera}/image", "camera_info": f"/{camera}/camera_info"}


def write_sequence_files(
    sequence: SyntheticSequence, out_dir, name: str, *, ring: list | None = None
) -> dict:
    """Write one pair as a PNG and PCD files; returns the written names (relative to out_dir).

    The points are :meth:`~nbcalib.synthetic.rig.SyntheticSequence.output_scans`; a moving rig
    (not motion-compensated) also gets one PCD per scan. ``ring``: ``(camera name, sequence)``
    of every camera of a ring (``sequence`` is the first's): an image per camera in its folder.
    """
    from nbcalib.io.image import write_png
    from nbcalib.io.pcd import write_pcd

    out_dir = Path(out_dir)
    if ring is None:
        write_png(out_dir / f"{name}.png", sequence.image)
        images = {"image": f"{name}.png"}
    else:
        images = {"images": {}}
        for camera, seq in ring:
            (out_dir / camera).mkdir(parents=True, exist_ok=True)
            write_png(out_dir / camera / f"{name}.png", seq.image)
            images["images"][camera] = f"{camera}/{name}.png"
    merged = [scan_fields(scan, time_offset=scan.stamp) for scan in sequence.output_scans()]
    write_pcd(
        out_dir / f"{name}.pcd",
        {key: np.concatenate([f[key] for f in merged]) for key in merged[0]},
    )
    written = {**images, "points": f"{name}.pcd"}
    if _moving(sequence):
        folder = out_dir / f"{name}_scans"
        folder.mkdir(parents=True, exist_ok=True)
        scans = []
        for k, scan in enumerate(sequence.scans):
            write_pcd(folder / f"scan_{k:04d}.pcd", scan_fields(scan))
            scans.append(f"{name}_scans/scan_{k:04d}.pcd")
        written["scans"] = scans
    return written


def write_sequence_bag(
    sequence: SyntheticSequence,
    path,
    fmt: str,
    *,
    stamp_ns: int,
    ring: list | None = None,
    given: GivenIntrinsics | None = None,
) -> None:
    """Write one pair as a ROS bag: tf_static, camera_info, the image, then every scan.

    The scans are :meth:`~nbcalib.synthetic.rig.SyntheticSequence.output_scans` (one
    motion-compensated cloud with ``"motion"`` in ``RigConfig.without``).

    Parameters
    ----------
    sequence : SyntheticSequence
        The pair.
    path : str or os.PathLike
        ``.bag`` file (``bag1``) or bag folder (``bag2``, ``mcap``).
    fmt : {"bag1", "bag2", "mcap"}
        Bag format.
    stamp_ns : int
        Stamp of the image and of the first scan, nanoseconds.
    ring : list of (str, SyntheticSequence), optional
        Every camera of a ring with its sequence (``sequence`` is the first's): each camera's
        transform, camera info and image on its own topics (:func:`ring_topics`).
    given : GivenIntrinsics, optional
        The camera info holds these intrinsics instead of the true ones (one camera).
    """
    from nbcalib.io.bag_writer import BagWriter

    lidar = FRAMES["lidar"]
    if ring is None:
        views = [(FRAMES["camera"], sequence, TOPICS)]
    else:
        views = [(camera, seq, ring_topics(camera)) for camera, seq in ring]
    with BagWriter(path, fmt) as bag:
        for frame, seq, _ in views:
            bag.write_tf_static(stamp_ns, lidar, frame, seq.T_lidar_camera)
        for frame, seq, topics in views:
            info = seq.camera if given is None else given.apply(seq.camera)
            bag.write_camera_info(topics["camera_info"], stamp_ns, info, frame)
            bag.write_image(topics["image"], stamp_ns, seq.image, frame)
        for scan in sequence.output_scans():
            scan_stamp = stamp_ns + round(scan.stamp * 1e9)
            bag.write_pointcloud(TOPICS["points"], scan_stamp, scan_fields(scan), lidar)


def ground_truth_dict(
    config: RigConfig, sequences_info: list[dict], T_camera_lidar, *, ring: list | None = None
) -> dict:
    """The content of ``ground_truth.json``.

    ``T_lidar_camera`` is ``[x, y, z, qx, qy, qz, qw]`` (``p_lidar = T_lidar_camera @ p_camera``,
    the ``calib.json`` direction) and ``T_camera_lidar`` the 4 x 4 inverse; the other keys
    describe the data (rig, LiDAR, scene, seed, modality gap, the differences switched off
    ``without``, pairs with their files and ground-truth poses). A ring (``ring``: its
    :class:`~nbcalib.synthetic.rig.RingCamera` list) adds ``cameras``: per camera its name,
    model, size, topics, ``T_lidar_camera``, ``T_camera_lidar`` and ``T_cam0_camera`` (the
    camera in the first camera's frame, ``[x, y, z, qx, qy, qz, qw]``), the first camera's at
    the top as for one camera.
    """
    T_camera_lidar = np.asarray(T_camera_lidar, dtype=np.float64)
    T_lidar_camera = np.linalg.inv(T_camera_lidar)
    truth = {
        "T_lidar_camera": [float(v) for v in pose_to_xyz_quat(T_lidar_camera)],
        "T_camera_lidar": T_camera_lidar.tolist(),
        "lidar": config.lidar,
        "camera_model": config.camera if config.camera_model is None else config.camera_model.model,
        "scene": config.scene,
        "seed": config.seed,
        "modality_gap": config.modality_gap,
        "without": list(config.without),
        "frames": FRAMES,
        "topics": TOPICS,
        "conventions": "docs/conventions.md: p_a = T_a_b p_b; quaternions xyzw; the world is "
        "the LiDAR frame at the start of each pair's first scan (= the image time)",
        "pairs": sequences_info,
    }
    if ring:
        T_cam0_lidar = ring[0].T_camera_lidar
        truth["cameras"] = [
            {
                "name": r.name,
                "camera_model": r.camera.model,
                "width": r.camera.width,
                "height": r.camera.height,
                "topics": ring_topics(r.name),
                "T_lidar_camera": [float(v) for v in pose_to_xyz_quat(invert_T(r.T_camera_lidar))],
                "T_camera_lidar": np.asarray(r.T_camera_lidar).tolist(),
                "T_cam0_camera": [
                    float(v) for v in pose_to_xyz_quat(T_cam0_lidar @ invert_T(r.T_camera_lidar))
                ],
            }
            for r in ring
        ]
    return truth


def _sequence_info(sequence: SyntheticSequence, stamp_ns: int, written: dict) -> dict:
    lidar = sequence.lidar
    # motion-compensated: one cloud at the image time
    stamps = sequence.scan_stamps if "motion" not in sequence.config.without else [0.0]
    info = {
        "name": pair_name(sequence.pair),
        **written,
        "image_stamp_ns": stamp_ns,
        "scan_stamps_ns": [stamp_ns + round(s * 1e9) for s in stamps],
        "scan_period": lidar.scan_period,
        "num_points": int(sum(len(s) for s in sequence.scans)),
        "motion": sequence.motion.kind,
        "lidar_config": asdict(lidar),
    }
    if _moving(sequence):
        # ground-truth T_world_lidar at each scan start, [x, y, z, qx, qy, qz, qw]; the world is
        # the LiDAR frame at the image time (static rigs: the identity throughout)
        info["T_world_lidar_scan_begin"] = [
            [round(float(v), 12) for v in pose_to_xyz_quat(T)] for T in sequence.scan_poses_begin
        ]
    return info


def export_dataset(
    config: RigConfig,
    out_dir,
    *,
    pairs: int = 1,
    fmt: str = "files",
    progress: bool | Callable[[int, int, str], None] | None = None,
    given: GivenIntrinsics | None = None,
) -> dict:
    """Simulate ``pairs`` pairs and write them, the camera and the ground truth to ``out_dir``.

    Parameters
    ----------
    config : RigConfig
        What to simulate.
    out_dir : str or os.PathLike
        Output folder (created; existing files of the same names are replaced).
    pairs : int
        Number of pairs (one scene and trajectory each, the same rig).
    fmt : {"files", "bag1", "bag2", "mcap"}
        PNG + PCD files, or one bag per pair.
    progress : bool or callable, optional
        ``True`` for a progress display (:class:`nbcalib.progress.Progress`: a bar on a
        terminal, step lines in a log, nothing when the ``nbcalib`` logger is quiet), or
        ``progress(done, total, what)`` after each simulated or written step.
    given : GivenIntrinsics, optional
        Write intrinsics that differ from the camera that rendered the images
        (:mod:`nbcalib.synthetic.intrinsics`; one camera, not a ring): ``camera.yaml`` and the
        bags' camera info hold them, ``ground_truth.json`` both cameras under ``intrinsics``.

    Returns
    -------
    dict
        The ground truth as written to ``out_dir/ground_truth.json``.
    """
    from nbcalib.io.camera_file import save_camera

    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    if pairs < 1:
        raise ValueError(f"pairs must be >= 1, got {pairs}")
    if given is not None and given.exact:
        given = None
    if given is not None and config.cameras:
        raise ValueError("given intrinsics are for one camera, not a ring")
    if given is not None:  # before the simulation, not after it
        given.check(config.camera if config.camera_model is None else config.camera_model.model)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    truth_path = out_dir / "ground_truth.json"
    if truth_path.exists():
        truth_path.unlink()  # a half-rewritten folder must not look complete
    with Progress(label="synth", enabled=progress is True) as display:

        def report(done: int, total: int, what: str) -> None:
            if callable(progress):
                progress(done, total, what)
            display.total = total
            display.update(done - display.done, what)

        infos, T_camera_lidar, camera = _export_pairs(config, out_dir, pairs, fmt, report, given)
    save_camera(out_dir / "camera.yaml", camera if given is None else given.apply(camera))
    ring = ring_cameras(config) if config.cameras else None
    for r in ring or ():
        (out_dir / r.name).mkdir(parents=True, exist_ok=True)
        save_camera(out_dir / r.name / "camera.yaml", r.camera)
    truth = ground_truth_dict(config, infos, T_camera_lidar, ring=ring)
    if given is not None:  # the camera that rendered the images, and the one the user has
        truth["intrinsics"] = {
            "rendered": camera.to_dict(),
            "given": given.apply(camera).to_dict(),
            "offset": given.to_dict(),
        }
    write_text_atomic(truth_path, json.dumps(truth, indent=2, sort_keys=True) + "\n")
    return truth


def _export_pairs(
    config: RigConfig, out_dir: Path, pairs: int, fmt: str, report, given=None
) -> tuple:
    """Simulate and write each pair; ``(infos, T_camera_lidar, camera)`` of the last one."""
    infos = []
    T_camera_lidar = None
    camera = None
    for pair in range(pairs):

        def step(done, total, what, pair=pair):
            # pairs have the same number of steps (the simulation's, then one for writing):
            # report the fraction of all of them
            report(
                pair * (total + 1) + done, pairs * (total + 1), f"pair {pair + 1}/{pairs}: {what}"
            )

        ring = None
        if config.cameras:
            sequences = generate_ring(config, pair=pair, progress=step)
            sequence = sequences[0]
            ring = [(f"cam{k}", seq) for k, seq in enumerate(sequences)]
        else:
            sequence = generate_sequence(config, pair=pair, progress=step)
        name = pair_name(pair)
        stamp_ns = BASE_STAMP_NS + pair * 1000 * 1_000_000_000
        if fmt == "files":
            written = write_sequence_files(sequence, out_dir, name, ring=ring)
        else:
            bag_name = f"{name}.bag" if fmt == "bag1" else name
            _remove(out_dir / bag_name)
            write_sequence_bag(
                sequence, out_dir / bag_name, fmt, stamp_ns=stamp_ns, ring=ring, given=given
            )
            written = {"bag": bag_name}
        infos.append(_sequence_info(sequence, stamp_ns, written))
        T_camera_lidar = sequence.T_camera_lidar
        camera = sequence.camera
        per_pair = len(sequence.scans) + 2  # the image, each scan, writing
        report((pair + 1) * per_pair, pairs * per_pair, f"pair {pair + 1}/{pairs}: written")
    return infos, T_camera_lidar, camera


def _remove(path: Path) -> None:
    """Delete a previous bag file or folder of the same name (re-running into the same OUT)."""
    import shutil

    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()
