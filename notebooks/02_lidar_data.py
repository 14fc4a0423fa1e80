# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     notebook_metadata_filter: -jupytext.text_representation
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 2. LiDAR data: files, bags, fields, per-point time and intensity
#
# Before calibrating anything, you have to read your LiDAR's data and know what is in it.
# A spinning LiDAR reports, per scan (one revolution, typically 0.1 s), tens of thousands of
# points, each with more than `x, y, z`: an **intensity** (how strongly the surface reflected),
# a **ring** (which of the lasers fired), and often a **time** (when, within the scan). They
# arrive as point files (PCD, PLY, KITTI `.bin`) or as `sensor_msgs/PointCloud2` messages in ROS
# bags.
#
# We make a recording whose answer we know with nbcalib's synthetic rig (a 64-beam LiDAR nodding
# in a room, a camera), write it the way users have their data (PCD files, a PNG, `camera.yaml`,
# and ROS 1 / ROS 2 / mcap bags), then read it back: first by hand, then with `nbcalib.io`.
# At the end, if the real data the project's benchmarks use is present, we read a KITTI scan
# and a ROS 1 bag the same way.

# %%
import io
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from nbcalib.io.bag import open_bag
from nbcalib.io.camera_file import load_camera
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.io.image import read_image
from nbcalib.io.pcd import read_pcd_fields, write_pcd
from nbcalib.io.pointcloud import read_pointcloud, select_intensity_field
from nbcalib.io.pointcloud2 import pointcloud2_to_fields
from nbcalib.preprocess.intensity import equalize_point_intensities
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.synthetic.writer import BASE_STAMP_NS, TOPICS, export_dataset, write_sequence_bag
from nbcalib.teaching import is_quick, plotter, real_data_dir, show, work_folder
from nbcalib.transforms import transform_points

QUICK = is_quick()  # smaller data when the test suite runs the notebooks
np.set_printoptions(precision=4, suppress=True)

# %% [markdown]
# ## A recording with a known answer
#
# A 64-beam spinning LiDAR (0.1 s per revolution, 1024 firings per revolution) nods in a room for
# 0.3 s (3 scans; 1 s in the full run) while a plumb_bob camera takes one grey image at the start
# of the first scan. `export_dataset` is what the command line's `nbcalib synth` runs; the same
# recording from a shell:
#
# ```bash
# nbcalib synth lidar_data_recording/files --lidar spinning64 --camera plumb_bob --seed 3 \
#     --duration 0.3 --image-size 640x480 --gray
# ```
#
# It writes `camera.yaml`, the image `pair_000.png`, all scans in `pair_000.pcd` (times in
# seconds since the image), one PCD per scan in `pair_000_scans/` (times since that scan's
# start), and `ground_truth.json`, the extrinsic the rig was built with.

# %%
config = RigConfig(
    lidar="spinning64",
    camera="plumb_bob",
    scene="room",
    seed=3,
    duration=0.3 if QUICK else 1.0,
    image_size=(640, 480) if QUICK else (1280, 960),
)
recording = work_folder("02_lidar_data").resolve()  # work/02_lidar_data here, emptied
truth = export_dataset(config, recording / "files", fmt="files")
for path in sorted((recording / "files").rglob("*")):
    if path.is_file():
        print(f"{path.relative_to(recording)!s:40s} {path.stat().st_size / 1e6:7.3f} MB")

# %% [markdown]
# The same pair as ROS bags (`--format bag1`, `bag2` or `mcap` on the command line): topics
# `/points` (PointCloud2, one message per scan), `/image`, `/camera_info` and `/tf_static`. We
# simulate the pair once more in memory (the seed fixes everything, so it is the same data) and
# write it in the three bag formats. `seq` also holds the ground truth we check against below.

# %%
seq = generate_sequence(config)
bags = {
    "ROS 1 (.bag)": recording / "pair_000.bag",
    "ROS 2 (sqlite3)": recording / "pair_000_ros2",
    "ROS 2 (mcap)": recording / "pair_000_mcap",
}
for (label, path), fmt in zip(bags.items(), ("bag1", "bag2", "mcap")):
    write_sequence_bag(seq, path, fmt, stamp_ns=BASE_STAMP_NS)
    size = sum(f.stat().st_size for f in ([path] if path.is_file() else path.rglob("*")))
    print(f"{label:16s} {path.name:16s} {size / 1e6:6.2f} MB")
print(f"{len(seq.scans)} scans, {sum(len(s) for s in seq.scans):,} points")

# %% [markdown]
# ## A PCD file, by hand
#
# PCD (the Point Cloud Library's format) is a text header, then the points. The header names
# the fields, their byte SIZE, TYPE (F float, U unsigned, I signed integer) and COUNT, the number
# of POINTS, and how the data is stored (`ascii`, `binary`, or LZF-compressed
# `binary_compressed`):

# %%
scan_path = recording / "files" / "pair_000_scans" / "scan_0000.pcd"
header_text = scan_path.read_bytes()[:400].split(b"DATA")[0].decode() + "DATA ..."
print(header_text)

# %% [markdown]
# That is enough to read it with a few lines of NumPy: the header gives a structured dtype (one
# record per point), the data after the `DATA` line is that dtype back to back (binary) or one
# text line per point (ascii).

# %%
PCD_TYPES = {"F": "f", "U": "u", "I": "i"}


def naive_read_pcd(path):
    """The fields of an ascii or binary PCD file (COUNT 1 fields), read by hand."""
    data = Path(path).read_bytes()
    header, pos = {}, 0
    while "DATA" not in header:
        end = data.index(b"\n", pos)
        line = data[pos:end].decode("ascii").strip()
        pos = end + 1
        if line and not line.startswith("#"):
            key, *values = line.split()
            header[key] = values
    dtype = np.dtype(
        [
            (name, f"<{PCD_TYPES[kind]}{size}")
            for name, size, kind in zip(header["FIELDS"], header["SIZE"], header["TYPE"])
        ]
    )
    n = int(header["POINTS"][0])
    encoding = header["DATA"][0]
    if encoding == "binary":
        table = np.frombuffer(data, dtype=dtype, count=n, offset=pos)
    elif encoding == "ascii":
        table = np.loadtxt(io.BytesIO(data[pos:]), dtype=dtype, ndmin=1)
    else:
        raise NotImplementedError(f"{encoding}: LZF-compressed columns, left to nbcalib.io")
    return {name: table[name] for name in dtype.names}


naive_fields = naive_read_pcd(scan_path)
print({name: (values.dtype.name, values.shape) for name, values in naive_fields.items()})

# %% [markdown]
# `nbcalib.io.pcd.read_pcd_fields` reads the same fields (and also `binary_compressed`, padding
# fields and multi-count fields). We also write the scan as `ascii` and as `binary_compressed`
# with `write_pcd` and read all of them back: every field must come back bit for bit, and equal
# to the simulated scan.

# %%
package_fields = read_pcd_fields(scan_path)
write_pcd(recording / "scan_0000_ascii.pcd", package_fields, encoding="ascii")
write_pcd(recording / "scan_0000_lzf.pcd", package_fields, encoding="binary_compressed")
ascii_fields = naive_read_pcd(recording / "scan_0000_ascii.pcd")
lzf_fields = read_pcd_fields(recording / "scan_0000_lzf.pcd")
scan = seq.scans[0]
simulated = {
    "x": scan.points[:, 0],
    "y": scan.points[:, 1],
    "z": scan.points[:, 2],
    "intensity": scan.intensities,
    "t": scan.times,
    "ring": scan.rings,
}
pcd_agree = {
    name: bool(
        np.array_equal(naive_fields[name], package_fields[name])
        and np.array_equal(ascii_fields[name], package_fields[name])
        and np.array_equal(lzf_fields[name], package_fields[name])
        and np.array_equal(package_fields[name], simulated[name].astype(package_fields[name].dtype))
    )
    for name in package_fields
}
print("naive == nbcalib == ascii == binary_compressed == simulation:", pcd_agree)
for suffix in ("", "_ascii", "_lzf"):
    path = recording / "files" / "pair_000_scans" / "scan_0000.pcd"
    path = path if not suffix else recording / f"scan_0000{suffix}.pcd"
    print(f"{path.name:22s} {path.stat().st_size / 1e6:5.2f} MB")

# %% [markdown]
# ## The cloud nbcalib works with
#
# `read_pointcloud` (PCD, PLY, KITTI `.bin`, `.npy`/`.npz`, by suffix) turns the fields into a
# `PointCloud`: the finite points as float64 (N, 3) in metres, the **intensity channel**, the
# **per-point times** in seconds relative to the scan, and every field as read. The intensity is
# chosen by the reference toolbox's rule: a field named `reflectivity` (Ouster, Livox) wins over
# `intensity`; you can name another one (`--intensity-channel`). The time field is the first of
# `t`, `time`, `time_stamp`, `timestamp`; integer times are nanoseconds, float times seconds.

# %%
cloud = read_pointcloud(scan_path)
print(f"{len(cloud):,} points, fields {list(cloud.fields)}")
print(f"intensity {cloud.intensity.min():.1f}..{cloud.intensity.max():.1f} (as stored)")
print(f"times {1e3 * cloud.times.min():.2f}..{1e3 * cloud.times.max():.2f} ms")
for names in (["x", "y", "z", "intensity"], ["x", "y", "z", "intensity", "reflectivity"]):
    print(f"fields {names}: intensity channel = {select_intensity_field(names)!r}")

# %% [markdown]
# ## The camera image and one scan from above
#
# The image read back from `pair_000.png`, and scan 0 seen from above (LiDAR frame: x forward,
# y left), coloured by intensity. One scan of a 64-beam LiDAR is sparse: rings with gaps between
# them, which is why the method first accumulates a dense cloud (notebook 3).

# %%
image = read_image(recording / "files" / "pair_000.png")
fig, axes = plt.subplots(1, 2, figsize=(15, 5.5))
axes[0].imshow(image, cmap="gray")
axes[0].set_title(f"pair_000.png, {image.shape[1]} x {image.shape[0]} px")
low = cloud.points[:, 2] < 1.0  # below the ceiling
dots = axes[1].scatter(
    cloud.points[low, 0], cloud.points[low, 1], s=0.3, c=cloud.intensity[low], cmap="gray"
)
axes[1].scatter([0], [0], marker="*", s=150, c="r", label="LiDAR")
axes[1].set_aspect("equal")
axes[1].set_xlabel("x (forward) [m]")
axes[1].set_ylabel("y (left) [m]")
axes[1].legend(loc="upper right")
axes[1].set_title("scan 0 from above (below z = 1 m), coloured by intensity")
fig.colorbar(dots, ax=axes[1], label="intensity (0-255)")
fig.tight_layout()

# %% [markdown]
# ## Rings and the sweep
#
# Each **ring** is one laser at a fixed elevation: ring 0 the lowest (-22.5 degrees), ring 63 the
# highest (+22.5). The head spins clockwise seen from above, starting behind the sensor
# (azimuth 180 degrees), so the **time** of a point says where the head was pointing: azimuth
# `180 - 360 t / 0.1 s` (wrapped). A motion-distorted scan is one in which the sensor moved
# during these 0.1 s: the per-point time is what lets notebook 3 undo it.

# %%
period = seq.lidar.scan_period
elevation_deg = np.degrees(np.arctan2(cloud.points[:, 2], np.hypot(*cloud.points[:, :2].T)))
azimuth_deg = np.degrees(np.arctan2(cloud.points[:, 1], cloud.points[:, 0]))
expected_azimuth = 180.0 - 360.0 * cloud.times / period
sweep_residual_deg = (azimuth_deg - expected_azimuth + 180.0) % 360.0 - 180.0
print(f"azimuth vs 180 - 360 t / T: largest gap {np.abs(sweep_residual_deg).max():.1e} deg")
print(f"(one firing column is {360 / seq.lidar.columns:.3f} deg, {1e6 * period / 1024:.0f} us)")

fig, axes = plt.subplots(1, 3, figsize=(17, 4.8))
every = 7  # fewer dots, same picture
axes[0].scatter(cloud.fields["ring"][::every], elevation_deg[::every], s=0.5)
axes[0].set_xlabel("ring")
axes[0].set_ylabel("elevation [deg]")
axes[0].set_title("ring = laser = elevation")
axes[1].scatter(azimuth_deg[::every], 1e3 * cloud.times[::every], s=0.5, c="k")
axes[1].set_xlabel("azimuth atan2(y, x) [deg]")
axes[1].set_ylabel("time in the scan [ms]")
axes[1].set_xlim(-180, 180)
axes[1].set_title("the sweep: clockwise from 180 deg (behind)")
order = np.argsort(cloud.times)[::every]
dots = axes[2].scatter(
    cloud.points[order, 0], cloud.points[order, 1], s=0.3, c=1e3 * cloud.times[order], cmap="plasma"
)
axes[2].set_aspect("equal")
axes[2].set_xlabel("x (forward) [m]")
axes[2].set_ylabel("y (left) [m]")
axes[2].set_title("scan 0 from above, coloured by time")
fig.colorbar(dots, ax=axes[2], label="time [ms]")
fig.tight_layout()

# %% [markdown]
# The file with every scan of the pair, `pair_000.pcd`, carries times since the image instead
# (scan k adds `k * 0.1 s`), which is what accumulation needs; its points are the scans one after
# the other.

# %%
pair_cloud = read_pointcloud(recording / "files" / "pair_000.pcd")
scan_sizes = [len(s) for s in seq.scans]
starts = np.cumsum([0, *scan_sizes[:-1]])
print(f"pair_000.pcd: {len(pair_cloud):,} points = {' + '.join(map(str, scan_sizes))}")
print("first time of each scan [s]:", pair_cloud.times[starts])

# %% [markdown]
# ## The same scans from a bag
#
# A bag is a log of timestamped messages on named topics. `nbcalib.io.bag` reads ROS 1 and
# ROS 2 bags (sqlite3 or mcap) without a ROS installation (through the `rosbags` package):
# topics, message counts, and the header stamps of the scans.

# %%
bag_path = bags["ROS 1 (.bag)"]
with open_bag(bag_path) as bag:
    for topic, msgtype in bag.topics.items():
        print(f"{topic:14s} {msgtype:28s} {bag.message_counts[topic]} messages")
    scan_stamps_ns = bag.stamps(TOPICS["points"])
print("scan stamps [s after the image]:", (np.array(scan_stamps_ns) - BASE_STAMP_NS) / 1e9)

# %% [markdown]
# A `sensor_msgs/PointCloud2` is a flat byte buffer plus a list of fields, each with a name, a
# byte offset within the point, a datatype code (7 = float32, 4 = uint16, ...) and a count;
# `point_step` is the size of one point. That is again a structured dtype, by hand:

# %%
DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}

with open_bag(bag_path) as bag:
    msg = next(m for _, m in bag.messages(TOPICS["points"]))  # the first scan
for f in msg.fields:
    print(f"  {f.name:10s} offset {f.offset:2d}  datatype {f.datatype} ({DATATYPES[f.datatype]})")
print(f"  point_step {msg.point_step} bytes, {msg.width * msg.height:,} points")
order_mark = ">" if msg.is_bigendian else "<"
message_dtype = np.dtype(
    {
        "names": [f.name for f in msg.fields],
        "formats": [order_mark + DATATYPES[f.datatype] for f in msg.fields],
        "offsets": [f.offset for f in msg.fields],
        "itemsize": msg.point_step,
    }
)
naive_message = np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=message_dtype)
message_fields = pointcloud2_to_fields(msg)
message_agree = all(
    np.array_equal(naive_message[name], message_fields[name]) for name in message_fields
)
print("naive decoding == pointcloud2_to_fields:", message_agree)

# %% [markdown]
# `Bag.pointclouds` yields a `PointCloud` per message, with the same rules as the file readers.
# The three bag formats hold the same scans, equal to the PCD files; `/tf_static` holds the
# extrinsic (`T_lidar_camera`, the camera's pose in the LiDAR frame, notebook 0) and
# `/camera_info` the camera.

# %%
bag_scans = {}  # label -> list of PointCloud, one per scan
for label, path in bags.items():
    with open_bag(path) as bag:
        bag_scans[label] = [c for _, c in bag.pointclouds()]
        tf_static = bag.tf_static()
        bag_camera = bag.camera_info()
scan_files = sorted((recording / "files" / "pair_000_scans").glob("scan_*.pcd"))
file_scans = [read_pointcloud(p) for p in scan_files]
bags_agree = all(
    len(scans) == len(file_scans)
    and all(
        np.array_equal(a.points, b.points)
        and np.array_equal(a.intensity, b.intensity)
        and np.array_equal(a.times, b.times)
        for a, b in zip(scans, file_scans)
    )
    for scans in bag_scans.values()
)
print(f"{len(file_scans)} scans in each bag, equal to the PCD files: {bags_agree}")
parent, child, T_parent_child = tf_static[0]
print(f"/tf_static: {parent} <- {child}, translation {T_parent_child[:3, 3]} m")
print(f"/camera_info: {bag_camera.model} {bag_camera.width} x {bag_camera.height}")

# %% [markdown]
# ## Intensity: raw and equalised
#
# Raw intensities are not comparable between sensors (0-255, 0-1, 0-65535, reflectivity or
# return strength), and their histogram is lopsided: most points are dim. The method therefore
# equalises them by rank (paper section III-C): a point's new value is its rank among all
# points, mapped onto 256 levels in [0, 1). Points with the same raw value share one level, the
# one of their mid-rank (nbcalib's tie rule; 8-bit LiDARs have ties everywhere).
#
# By hand: sort the distinct values, count them, and give each its mid-rank level. Then
# `nbcalib.preprocess.intensity.equalize_point_intensities`: they must agree.

# %%
raw = cloud.intensity
values, inverse, counts = np.unique(raw, return_inverse=True, return_counts=True)
first_rank = np.cumsum(counts) - counts  # rank of the first point of each distinct value
twice_mid_rank = 2 * first_rank + counts - 1
naive_equalised = (np.floor(256 * twice_mid_rank / (2 * len(raw))) / 256)[inverse]
equalised = equalize_point_intensities(raw)
equalise_gap = np.abs(naive_equalised - equalised).max()
print(f"{len(values):,} distinct raw values among {len(raw):,} points")
print(f"naive vs equalize_point_intensities: largest gap {equalise_gap:.1e}")

# %% [markdown]
# The histograms, and the scan laid out as a LiDAR "image": one row per ring, one column per
# firing (the column number is the per-point time divided by the 98 us between firings). The
# equalised image shows the room's texture with even contrast. Blue marks firings without a
# return: scattered random dropouts, and the two windows, whose glass the simulated LiDAR mostly
# loses, as real ones do.

# %%
columns = seq.lidar.columns
column = np.round(cloud.times / (period / columns)).astype(int)
ring = cloud.fields["ring"].astype(int)
raw_hist, raw_edges = np.histogram(raw, bins=64, range=(0, 256))
eq_hist, eq_edges = np.histogram(equalised, bins=64, range=(0, 1))
lidar_images = {}
for label, values_k in (("raw", raw / 255.0), ("equalised", equalised)):
    grid = np.full((seq.lidar.beams, columns), np.nan)
    grid[ring, column] = values_k
    lidar_images[label] = grid

fig, axes = plt.subplots(
    2, 2, figsize=(16, 6.5), gridspec_kw={"width_ratios": [1, 3]}, layout="constrained"
)
grey_with_gaps = plt.get_cmap("gray").with_extremes(bad="tab:blue")  # NaN: no return
for row, (label, hist, edges) in enumerate(
    (("raw", raw_hist, raw_edges), ("equalised", eq_hist, eq_edges))
):
    axes[row, 0].stairs(hist, edges, fill=True)
    axes[row, 0].set_xlabel("raw intensity (0-255)" if row == 0 else "equalised intensity")
    axes[row, 0].set_ylabel("points")
    axes[row, 0].set_title(f"{label}: {hist.sum():,} points")
    shown = axes[row, 1].imshow(
        lidar_images[label],
        cmap=grey_with_gaps,
        origin="lower",
        aspect="auto",
        vmin=0,
        vmax=1,
        extent=(-0.5, columns - 0.5, -0.5, seq.lidar.beams - 0.5),
    )
    axes[row, 1].set_xlabel("firing column (azimuth 180 deg at 0, clockwise)")
    axes[row, 1].set_ylabel("ring")
    axes[row, 1].set_title(f"scan 0, ring x column, {label} intensity (blue: no return)")
colorbar = fig.colorbar(shown, ax=axes[:, 1], label="intensity (raw / 255, or equalised)")

# %% [markdown]
# ## Does the recording line up with its ground truth?
#
# Everything a calibration needs is now on disk: the camera (`camera.yaml`), the image, the
# scans, and here also the answer (`ground_truth.json`, which stores `T_lidar_camera` like
# `calib.json`, and `read_ground_truth` returns `T_camera_lidar`). We project the points with the
# true extrinsic read from the files: coloured by range, they follow the image's edges. We use
# the points deskewed with the true trajectory (`seq.dense_cloud()`), so that motion distortion
# plays no part yet (notebook 3 deals with it).

# %%
camera = load_camera(recording / "files" / "camera.yaml")
T_camera_lidar = read_ground_truth(recording / "files" / "ground_truth.json")
points, intensities = seq.dense_cloud()
uv, valid = camera.project(transform_points(T_camera_lidar, points), in_image=True)
depth = np.linalg.norm(points[valid], axis=1)
print(f"{valid.sum():,} of {len(points):,} points in the image")

fig, ax = plt.subplots(figsize=(10, 7.5))
ax.imshow(image, cmap="gray")
dots = ax.scatter(uv[valid, 0], uv[valid, 1], s=0.3, c=depth, cmap="turbo", alpha=0.6)
fig.colorbar(dots, ax=ax, shrink=0.8, label="range [m]")
ax.set_title(f"{valid.sum():,} LiDAR points projected with the true T_camera_lidar")
ax.set_axis_off()

# %% [markdown]
# ## In 3-D
#
# The deskewed cloud of all scans, coloured by equalised intensity: interactive in JupyterLab
# (`pip install 'nbcalib[notebooks]'`), a still picture without a display.

# %%
pl = plotter()
image_3d = None  # the rendered view (None when it opened interactively)
if pl is not None:
    import pyvista as pv

    step = 4 if QUICK else 1
    below = points[::step, 2] < 1.0  # without the ceiling, to look into the room
    cloud_3d = pv.PolyData(points[::step][below])
    cloud_3d["equalised intensity"] = equalize_point_intensities(intensities)[::step][below]
    pl.add_points(cloud_3d, scalars="equalised intensity", cmap="gray", point_size=2)
    pl.add_axes()
    pl.camera_position = [(-6.0, -8.0, 8.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)]
    image_3d = show(pl, "the deskewed scans, equalised intensity (ceiling left out)")

# %% [markdown]
# ## Real data: a KITTI scan and a ROS 1 bag
#
# The project's benchmarks use a few public real recordings, kept beside the repository in
# `../shared/data/real` (not shipped with nbcalib; set `NBCALIB_REAL_DATA` to another folder).
# If they are there, we read one KITTI Velodyne HDL-64E scan (`velodyne.bin`: float32 records
# `x, y, z, reflectance`, no header, no time, no ring) and the same frame from a ROS 1 bag.

# %%
REAL = real_data_dir()  # $NBCALIB_REAL_DATA, else ../shared/data/real beside the project
kitti_bin = REAL / "kitti_raw_2011_09_26" / "0000000000" / "velodyne.bin"
kitti_bag = REAL / "bags" / "kitti_2011_09_26_udacity_5frames.bag"
kitti = kitti_from_bag = None
if kitti_bin.is_file() and kitti_bag.is_file():
    records = np.fromfile(kitti_bin, dtype=np.float32).reshape(-1, 4)  # by hand
    kitti = read_pointcloud(kitti_bin)
    kitti_agree = np.array_equal(records[:, :3], kitti.points) and np.array_equal(
        records[:, 3], kitti.intensity
    )
    print(
        f"{kitti_bin.name}: {len(kitti):,} points, fields {list(kitti.fields)}, times {kitti.times}"
    )
    print(f"by hand == read_pointcloud: {kitti_agree}")
    print(
        f"reflectance {kitti.intensity.min():.2f}..{kitti.intensity.max():.2f}, "
        f"{np.unique(kitti.intensity).size} distinct values"
    )
    with open_bag(kitti_bag) as bag:
        for topic, msgtype in bag.topics.items():
            print(f"  {topic:40s} {msgtype:28s} {bag.message_counts[topic]} messages")
        kitti_points_topic = bag.select_topic("point cloud")
        kitti_msg = next(m for _, m in bag.messages(kitti_points_topic))
        kitti_from_bag = next(c for _, c in bag.pointclouds(kitti_points_topic, only={0}))
        kitti_tf = bag.tf_static()
    print(
        f"  PointCloud2 fields: {[(f.name, DATATYPES[f.datatype]) for f in kitti_msg.fields]}, "
        f"frame {kitti_msg.header.frame_id!r}"
    )
    kitti_bag_agree = np.array_equal(kitti_from_bag.points, kitti.points) and np.array_equal(
        kitti_from_bag.intensity, kitti.intensity
    )
    print(f"  first bag message == velodyne.bin: {kitti_bag_agree}")
    print(f"  /tf_static: {kitti_tf[0][0]} <- {kitti_tf[0][1]}")
else:
    print(
        f"No real data at {REAL}: this section is skipped (the rest of the notebook does not "
        "need it)."
    )

# %% [markdown]
# KITTI's scans carry no time field, and the file is not in firing order either: it holds the
# points laser by laser, each laser's run one full turn of the head in azimuth. A per-point time
# would have to come from the azimuth (the head turns at a constant rate). The reflectance has
# only 100 distinct values, and over a quarter of the points have reflectance 0: with the tie
# rule they all share one equalised level (the spike), whatever order they come in.

# %%
if kitti is not None:
    k_azimuth = np.degrees(np.arctan2(kitti.points[:, 1], kitti.points[:, 0]))
    k_elevation = np.degrees(np.arctan2(kitti.points[:, 2], np.hypot(*kitti.points[:, :2].T)))
    k_turns = int(np.sum(np.diff(k_azimuth) < -180.0))  # the azimuth wraps from +180 to -180
    k_equalised = equalize_point_intensities(kitti.intensity)
    zero_share = float(np.mean(kitti.intensity == 0))
    zero_level = float(np.unique(k_equalised[kitti.intensity == 0])[0])
    print(f"{k_turns} turns of the head in the file (one per laser)")
    print(
        f"{100 * zero_share:.0f} % of the points have reflectance 0 -> one level, {zero_level:.3f}"
    )

    fig, axes = plt.subplots(1, 3, figsize=(17, 4.8))
    near = np.hypot(*kitti.points[:, :2].T) < 30.0
    axes[0].scatter(*kitti.points[near, :2].T, s=0.2, c=k_equalised[near], cmap="gray")
    axes[0].set_aspect("equal")
    axes[0].set_xlabel("x (forward) [m]")
    axes[0].set_ylabel("y (left) [m]")
    axes[0].set_title("KITTI frame 0 within 30 m, equalised reflectance")
    first = slice(0, 7000)  # the first few lasers
    dots = axes[1].scatter(
        np.arange(len(kitti))[first], k_azimuth[first], s=0.5, c=k_elevation[first], cmap="viridis"
    )
    fig.colorbar(dots, ax=axes[1], label="elevation [deg]")
    axes[1].set_xlabel("point index in the file")
    axes[1].set_ylabel("azimuth [deg]")
    axes[1].set_title("the first 7000 points: laser by laser, a turn each")
    axes[2].hist(kitti.intensity, bins=100, range=(0, 1), label="raw reflectance")
    axes[2].hist(k_equalised, bins=100, range=(0, 1), histtype="step", lw=2, label="equalised")
    axes[2].set_xlabel("reflectance (0-1)")
    axes[2].set_ylabel("points")
    axes[2].legend()
    axes[2].set_title(f"{len(kitti):,} points; the spike: reflectance 0")
    fig.tight_layout()

# %% [markdown]
# ## On your own data
#
# - `read_pointcloud("scan.pcd")` (or `.ply`, `.bin`, `.npy`): look at `cloud.fields`, then
#   `cloud.intensity` and `cloud.times` (None when there is no time field).
# - `with open_bag("run.bag") as bag: bag.topics` lists what a bag holds; `bag.pointclouds()`
#   reads its point clouds.
# - `nbcalib preprocess` does all of this for a whole recording (notebook 3 onwards).
#
# Next: [03_dense_clouds](03_dense_clouds.py), turning sparse moving scans into one dense cloud.

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - the recording's ground truth is the extrinsic the rig was built with, 5-30 cm from the
#   LiDAR; one 0.1 s scan of 64 rings per 0.1 s of data, per-point times in order;
# - the hand-written PCD reader, `read_pcd_fields`, the ascii and binary_compressed copies and
#   the simulation agree bit for bit; the three bags hold the same scans as the PCD files, and
#   their `/tf_static` is the true `T_lidar_camera`;
# - the hand-decoded PointCloud2 equals `pointcloud2_to_fields`;
# - elevation follows the ring, azimuth follows the time (within one firing column);
# - the hand-made equalisation equals `equalize_point_intensities`, both histograms count every
#   point, and the equalised one is flat;
# - the points projected with the true extrinsic from the files land on the surface the camera
#   saw at that pixel;
# - where the real data is present: the KITTI scan read by hand equals `read_pointcloud` and the
#   bag's first message, with fields x, y, z, intensity and no time, stored as 64 turns; its
#   zero-reflectance points share one equalised level. Where it is absent, the section says so
#   and leaves nothing behind.
