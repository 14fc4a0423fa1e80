"""Which matcher and which image normalisation work across the LiDAR-intensity vs camera gap.

For each LiDAR-image / camera-image pair with a known ``T_camera_lidar``, every matcher is run
with several normalisations of the two images. A match is *correct* when the LiDAR keypoint,
lifted to its 3-D point through the index map (nearest filled pixel within 2 px), projects with
the true ``T_camera_lidar`` within ``--tol`` pixels (8) of the camera keypoint. Reported per
matcher and normalisation: matches, correct matches, inlier ratio (correct / liftable
matches), CPU and wall seconds per pair.

Pairs:

- synthetic (``nbcalib.synthetic``): the dense cloud of a nodding LiDAR, rendered by the
  virtual camera as ``nbcalib preprocess`` does (equalised intensities, z-buffer);
- real, when ../shared/data/real exists: KITTI raw frames (a single HDL-64 scan each) and the
  two PJLab frames, rendered the same way.

Run (a few minutes per matcher; the learned matchers need ``nbcalib models export`` first)::

    python benchmarks/bench_matching.py --model-dir ~/.cache/nbcalib/models \\
        --out bench_matching.json

Prints a Markdown table (the one in docs/BENCHMARKS.md, "Matching").
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "real"

#: (camera normalisation, LiDAR normalisation, LiDAR fill radius)
NORMALISATIONS = {
    "none": ("none", "none", 0),
    "fill": ("none", "none", 2),
    "invert-lidar": ("none", "invert", 2),
    "clahe-nofill": ("clahe", "clahe", 0),
    "clahe": ("clahe", "clahe", 2),
    "gradient": ("gradient", "gradient", 2),
}

SYNTHETIC = [
    ("spinning64", "pinhole", "street", 0),
    ("spinning64", "pinhole", "room", 1),
    ("livox", "pinhole", "room", 2),
    ("spinning32", "fisheye", "street", 3),
]


# --------------------------------------------------------------------------------------------
# Pairs


def _render(points, intensities):
    """LiDAR image and index map as ``nbcalib preprocess`` makes them."""
    from nbcalib.preprocess.intensity import equalize_point_intensities
    from nbcalib.preprocess.lidar_image import (
        estimate_lidar_fov,
        make_virtual_camera,
        render_lidar_image,
    )

    equalised = equalize_point_intensities(intensities)
    vcam, T_vcam_lidar = make_virtual_camera(estimate_lidar_fov(points))
    image = render_lidar_image(vcam, T_vcam_lidar, points, equalised)
    return image.intensity, image.index, vcam


def synthetic_pair(lidar, camera, scene, seed):
    from nbcalib.preprocess.intensity import equalize_image
    from nbcalib.synthetic import RigConfig, generate_sequence

    seq = generate_sequence(RigConfig(lidar=lidar, camera=camera, scene=scene, seed=seed))
    points, intensities = seq.dense_cloud()
    lidar_image, index, vcam = _render(points, intensities)
    return {
        "vcam": vcam,
        "name": f"synthetic {lidar} {camera} {scene}",
        "camera_image": equalize_image(seq.image),
        "lidar_image": lidar_image,
        "index": index,
        "points": points,
        "camera": seq.camera,
        "T_camera_lidar": seq.T_camera_lidar,
    }


def _real_pair(name, points, intensities, image_path, calib_path):
    from nbcalib.camera import create_camera
    from nbcalib.io.image import read_image
    from nbcalib.preprocess.intensity import equalize_image

    calib = json.loads(Path(calib_path).read_text())
    K = np.asarray(calib["K"])
    dist = [float(x) for x in calib.get("dist", [])]
    image = read_image(image_path, grey=True)
    height, width = image.shape
    model = "plumb_bob" if any(dist) else "pinhole"
    camera = create_camera(
        model, [K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist if any(dist) else [], width, height
    )
    lidar_image, index, vcam = _render(points, intensities)
    return {
        "vcam": vcam,
        "name": name,
        "intensities": intensities,
        "camera_image": equalize_image(image),
        "lidar_image": lidar_image,
        "index": index,
        "points": points,
        "camera": camera,
        "T_camera_lidar": np.asarray(calib["T_cam_lidar"], dtype=np.float64),
    }


def kitti_pair(frame: int):
    root = REAL / "kitti_raw_2011_09_26"
    scan = np.fromfile(root / f"{frame:010d}" / "velodyne.bin", np.float32).reshape(-1, 4)
    points = scan[:, :3].astype(np.float64)
    keep = np.linalg.norm(points, axis=1) > 1.0
    return _real_pair(
        f"KITTI {frame:02d} (1 scan)",
        points[keep],
        scan[keep, 3].astype(np.float64),
        root / f"{frame:010d}" / "image_02.png",
        root / "calib" / "calib_normalized_cam2rect.json",
    )


def kitti_accumulated_pair(count: int):
    """The first ``count`` KITTI scans accumulated with motion compensation, image of frame 0."""
    from nbcalib.odometry import integrate_dynamic

    root = REAL / "kitti_raw_2011_09_26"
    scans = [
        np.fromfile(root / f"{i:010d}" / "velodyne.bin", np.float32).reshape(-1, 4).astype(float)
        for i in range(count)
    ]
    cloud = integrate_dynamic(scans)  # in the LiDAR frame of scan 0, the image's
    return _real_pair(
        f"KITTI 00 ({count} scans accumulated)",
        cloud.points,
        cloud.intensity,
        root / f"{0:010d}" / "image_02.png",
        root / "calib" / "calib_normalized_cam2rect.json",
    )


def pjlab_pair(folder: str):
    from nbcalib.io.pointcloud import read_pointcloud

    root = REAL / "pjlab" / folder
    cloud = read_pointcloud(root / "lidar.pcd")
    keep = np.linalg.norm(cloud.points, axis=1) > 1.0
    calib = sorted(root.glob("calib_normalized*.json"))[0]
    return _real_pair(
        f"PJLab {folder}", cloud.points[keep], cloud.intensity[keep], root / "image.png", calib
    )


# --------------------------------------------------------------------------------------------
# Scoring


def lift(uv_lidar: np.ndarray, index: np.ndarray, radius: int = 2) -> np.ndarray:
    """Point index of each LiDAR keypoint: its pixel, else the nearest filled one within radius."""
    height, width = index.shape
    out = np.full(len(uv_lidar), -1, dtype=np.int64)
    offsets = [(du, dv) for dv in range(-radius, radius + 1) for du in range(-radius, radius + 1)]
    offsets.sort(key=lambda o: o[0] ** 2 + o[1] ** 2)
    pixels = np.floor(uv_lidar + 0.5).astype(np.int64)
    for k, (u, v) in enumerate(pixels):
        for du, dv in offsets:
            uu, vv = u + du, v + dv
            if 0 <= uu < width and 0 <= vv < height and index[vv, uu] >= 0:
                out[k] = index[vv, uu]
                break
    return out


def score(pair, matches, tol_px: float) -> dict:
    from nbcalib.transforms import transform_points

    uv_camera, uv_lidar, _ = matches.matched()
    ids = lift(uv_lidar, pair["index"])
    liftable = ids >= 0
    points_camera = transform_points(pair["T_camera_lidar"], pair["points"][ids[liftable]])
    uv, valid = pair["camera"].project(points_camera)
    error = np.full(len(ids), np.inf)
    error[np.flatnonzero(liftable)[valid]] = np.linalg.norm(
        uv[valid] - uv_camera[liftable][valid], axis=1
    )
    correct = int(np.count_nonzero(error < tol_px))
    return {
        "keypoints_camera": len(matches.kpts_camera),
        "keypoints_lidar": len(matches.kpts_lidar),
        "matches": len(ids),
        "liftable": int(liftable.sum()),
        "correct": correct,
        "inlier_ratio": correct / max(int(liftable.sum()), 1),
    }


# --------------------------------------------------------------------------------------------
# Main


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model-dir", default=None)
    parser.add_argument(
        "--matchers", default="aliked-lightglue,disk-lightglue,xfeat-lighterglue,sift"
    )
    parser.add_argument("--normalisations", default=",".join(NORMALISATIONS))
    parser.add_argument("--max-keypoints", type=int, default=1024)
    parser.add_argument("--max-image-side", type=int, default=2048)
    parser.add_argument("--match-threshold", type=float, default=0.01)
    parser.add_argument("--tol", type=float, default=8.0, help="correct-match tolerance, px")
    parser.add_argument("--synthetic", type=int, default=len(SYNTHETIC), help="synthetic pairs")
    parser.add_argument("--kitti", default="0,10,19", help="KITTI frames ('' = none)")
    parser.add_argument(
        "--kitti-accumulate", type=int, default=20, help="also KITTI frames 0..N-1 accumulated"
    )
    parser.add_argument("--pjlab", default="auto_calib,manual_calib_0", help="PJLab folders")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--out", default=None, help="write all results as JSON")
    parser.add_argument("--save-pictures", default=None, help="folder for match pictures")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from nbcalib.matching import camera_scale_for, draw_matches, match_images

    makers = [(lambda c=c: synthetic_pair(*c)) for c in SYNTHETIC[: args.synthetic]]
    if REAL.is_dir():
        makers += [(lambda f=int(f): kitti_pair(f)) for f in args.kitti.split(",") if f]
        if args.kitti_accumulate:
            makers.append(lambda: kitti_accumulated_pair(args.kitti_accumulate))
        makers += [(lambda f=f: pjlab_pair(f)) for f in args.pjlab.split(",") if f]
    matchers = [m for m in args.matchers.split(",") if m]
    norms = [n for n in args.normalisations.split(",") if n]
    results = []
    for make in makers:
        pair = make()
        print(
            f"# {pair['name']}: camera {pair['camera_image'].shape[::-1]}, LiDAR image "
            f"{pair['lidar_image'].shape[::-1]}",
            file=sys.stderr,
        )
        for matcher in matchers:
            for norm in norms:
                cam_norm, lidar_norm, fill = NORMALISATIONS[norm]
                wall, cpu = time.perf_counter(), time.process_time()
                m = match_images(
                    pair["camera_image"],
                    pair["lidar_image"],
                    matcher=matcher,
                    match_threshold=args.match_threshold,
                    camera_scale=camera_scale_for(pair["camera"], pair["vcam"]),
                    max_image_side=args.max_image_side,
                    camera_normalization=cam_norm,
                    lidar_normalization=lidar_norm,
                    lidar_fill_radius=fill,
                    max_keypoints=args.max_keypoints,
                    model_dir=args.model_dir,
                    threads=args.threads,
                )
                wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
                row = {"pair": pair["name"], "matcher": matcher, "normalisation": norm}
                row.update(score(pair, m, args.tol))
                row.update({"wall_s": round(wall, 2), "cpu_s": round(cpu, 2)})
                results.append(row)
                print(json.dumps(row), file=sys.stderr)
                if args.save_pictures:
                    from nbcalib.io.image import write_png

                    folder = Path(args.save_pictures)
                    folder.mkdir(parents=True, exist_ok=True)
                    stem = f"{pair['name']}_{matcher}_{norm}".replace(" ", "_")
                    write_png(
                        folder / f"{stem}.png",
                        draw_matches(pair["camera_image"], pair["lidar_image"], m),
                    )
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=1))
    print_table(results)
    return 0


def print_table(results) -> None:
    """Markdown: per matcher and normalisation, summed over pairs, and per pair for the best."""
    keys = sorted({(r["matcher"], r["normalisation"]) for r in results}, key=str)
    print(
        "| matcher | normalisation | matches | correct | inlier ratio | pairs with >= 20 "
        "correct | CPU s / pair | wall s / pair |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for matcher, norm in keys:
        rows = [r for r in results if r["matcher"] == matcher and r["normalisation"] == norm]
        matches = sum(r["matches"] for r in rows)
        correct = sum(r["correct"] for r in rows)
        liftable = sum(r["liftable"] for r in rows)
        good = sum(r["correct"] >= 20 for r in rows)
        cpu = np.mean([r["cpu_s"] for r in rows])
        wall = np.mean([r["wall_s"] for r in rows])
        print(
            f"| {matcher} | {norm} | {matches} | {correct} | {correct / max(liftable, 1):.2f} "
            f"| {good}/{len(rows)} | {cpu:.1f} | {wall:.1f} |"
        )


if __name__ == "__main__":
    sys.exit(main())
