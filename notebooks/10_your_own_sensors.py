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
# # 10. Your own sensors: from a bag to an exported calibration
#
# You have a LiDAR and a camera on a rig, and a recording of both. This notebook walks through
# what you type, step by step, on the command line:
#
# 1. **look into the recording**: which topics hold the points, the image, the camera info;
# 2. **preprocess** with those topic names: a work directory with the dense cloud, the image and
#    the LiDAR image;
# 3. **find-matches** and **initial-guess**: the automatic start (notebook 5), and its success
#    flag;
# 4. **the fail-safe**: when the automatic guess fails, click a few corresponding points in the
#    camera image and the LiDAR image (`nbcalib.initial_guess.picker.ManualPicker`), save them,
#    and `nbcalib initial-guess WORK --manual FILE`;
# 5. **calibrate** and **report**: fine registration and the quality check;
# 6. **export** the result for ROS (tf2, URDF) and OpenCV.
#
# A synthetic recording stands in for yours (`nbcalib synth --format bag1`, a ROS 1 bag): it
# comes with the true extrinsic, so at the end `nbcalib evaluate` can say how far off each step
# was. With your own bag you skip that step (or compare with a calibration you trust).

# %%
import json
from pathlib import Path

import cv2
import matplotlib.pyplot as plt
import numpy as np

from nbcalib.initial_guess.picker import ManualPicker
from nbcalib.io.bag import open_bag, read_images
from nbcalib.io.calib_json import read_calib_json
from nbcalib.io.camera_file import load_camera
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.io.image import read_image
from nbcalib.matching.correspondences import lift_lidar_pixels
from nbcalib.metrics import pose_errors
from nbcalib.preprocess.lidar_image import visible_mask
from nbcalib.teaching import is_quick, plotter, real_data_dir, show, work_folder
from nbcalib.workdir import WorkDir, get_virtual_camera

QUICK = is_quick()
TMP = work_folder("10_your_own_sensors")  # all it writes: work/10_... here, emptied first
print("working in", TMP)

# %% [markdown]
# `nbcalib_command` runs one `nbcalib` command in this process, with the words a shell would pass
# (`nbcalib.cli.main`; a terminal prints the same), and prints the command before its output.
# In a terminal you would type the same words after `nbcalib`.


# %%
from nbcalib.teaching import nbcalib_command

# %% [markdown]
# ## The recording
#
# `nbcalib synth` simulates a 64-beam LiDAR nodding up and down in a room (the collection
# procedure the method asks for: move the LiDAR a little so that its rings fill the gaps) and a
# pinhole camera that takes one image at the start, with the rig at rest. `--format bag1` writes
# a ROS 1 bag (`bag2` and `mcap`: ROS 2); `ground_truth.json` holds the answer.
# In quick mode the recording is half a second long.

# %%
RECORDING = TMP / "recording"
nbcalib_command(
    "synth",
    RECORDING,
    "--format",
    "bag1",
    "--lidar",
    "spinning64",
    "--camera",
    "pinhole",
    "--image-size",
    "640x480",
    "--duration",
    "0.5" if QUICK else "1.5",
    "--seed",
    "0",
)
BAG = next(RECORDING.glob("*.bag"))
GROUND_TRUTH = RECORDING / "ground_truth.json"
print(sorted(p.name for p in RECORDING.iterdir()))

# %% [markdown]
# ## 1. Which topics?
#
# nbcalib reads bags without ROS (the pure-Python `rosbags` package). To see what a bag holds,
# ask `rosbags` directly (the naive way), or nbcalib's reader, `nbcalib.io.bag.open_bag`, which
# the command line uses: the same topics, types and message counts.

# %%
from rosbags.highlevel import AnyReader  # the naive way


def naive_topics(path):
    with AnyReader([Path(path)]) as reader:
        return {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}


def package_topics(path):
    with open_bag(path) as bag:
        return {t: (bag.topics[t], bag.message_counts[t]) for t in bag.topics}


topics = package_topics(BAG)
same_topics = naive_topics(BAG) == topics
print(f"{BAG.name}: (rosbags and nbcalib agree: {same_topics})")
for topic, (msgtype, count) in topics.items():
    print(f"  {topic:40s} {msgtype:30s} {count:3d} messages")

# %% [markdown]
# On the command line, `nbcalib topics BAG` prints the same list, and which topic `preprocess`
# would read for each kind: the one topic of that kind, or, when there are several, the option
# that names one (`--points-topic`, `--image-topic`, `--camera-info-topic`).

# %%
topics_status, topics_text = nbcalib_command("topics", BAG)

# %% [markdown]
# A real bag looks the same. When nbcalib's developers' copy of the real data is there
# (`../shared/data/real/bags`: five KITTI frames as ROS 1, ROS 2 sqlite3 and ROS 2 mcap bags),
# here are their topics too: a topic per sensor, with the names the KITTI driver chose.

# %%
REAL_BAGS = real_data_dir() / "bags"  # $NBCALIB_REAL_DATA, else ../shared/data/real
real_topics = {}
if REAL_BAGS.is_dir():
    for path in sorted(REAL_BAGS.iterdir()):
        real_topics[path.name] = package_topics(path)
        print(path.name)
        for topic, (msgtype, count) in real_topics[path.name].items():
            print(f"  {topic:40s} {msgtype:30s} {count:3d} messages")
else:
    print(f"no real bags at {REAL_BAGS}: nothing more to list")

# %% [markdown]
# ## 2. Preprocess, with the topic names
#
# For your bag, put your topic names here. The camera comes from the bag's CameraInfo (or
# `--camera FILE`: a ROS camera_info YAML, an OpenCV YAML, a calib.json). nbcalib chooses how
# to build the dense cloud (a LiDAR at rest: accumulate; a moving spinning LiDAR: continuous-
# time ICP, notebook 3) and says which.

# %%
WORK = TMP / "work"
status, _ = nbcalib_command(
    "preprocess",
    BAG,
    WORK,
    "--points-topic",
    "/points",
    "--image-topic",
    "/image",
    "--camera-info-topic",
    "/camera_info",
)
assert status == 0
print(sorted(p.name for p in WORK.iterdir()))

# %% [markdown]
# What it wrote, per pair (the data name is the bag's): the camera image as used (grey,
# equalised), and the LiDAR image: the dense cloud rendered by a virtual camera (here a
# 360-degree equirectangular one), whose index map gives the point behind each pixel
# (notebook 4).

# %%
work = WorkDir(WORK)
name = work.names()[0]
pair = work.load_pair(name)
camera = load_camera(WORK / "calib.json")
print(f"data name {name!r}: {len(pair.points_lidar):,} points;", camera)
fig, axes = plt.subplots(1, 2, figsize=(14, 4), width_ratios=[1, 2])
axes[0].imshow(pair.image, cmap="gray", vmin=0, vmax=255)
axes[0].set_title(f"{name}.png (camera)")
axes[1].imshow(pair.lidar_image.intensity, cmap="gray", vmin=0, vmax=255)
axes[1].set_title(f"{name}_lidar_intensities.png (LiDAR)")
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()

# %% [markdown]
# ## 3. The automatic initial guess
#
# `find-matches` matches the camera image against camera-shaped views of the cloud;
# `initial-guess` turns the matches into a pose and tests it. On your machine
# `--matcher auto` uses the learned matcher that ships with nbcalib; the test suite hides it, so
# there SIFT runs, which rarely matches across the LiDAR-camera gap. In quick mode we also skip
# the retries at finer views (`--no-retries`).

# %%
nbcalib_command("find-matches", WORK, *(["--no-retries"] if QUICK else []))
auto_status, _ = nbcalib_command("initial-guess", WORK)
# what initial-guess recorded (nothing when the guess failed: it writes no failed guess)
guesses = read_calib_json(WORK / "calib.json").record.initial_guess  # None: none recorded
auto_record = guesses.stages.get("init_T_lidar_camera_auto") if guesses else None
print(
    "automatic guess:",
    "passed its test" if auto_status == 0 else f"failed its test (exit status {auto_status})",
)

# %% [markdown]
# The matches it found are drawn in `WORK/<name>_matches.png`: the camera image on the left,
# the best LiDAR view on the right. When most lines join different things, no pose explains
# them, and the guess fails (whether it did is printed above).

# %%
matches_image = read_image(work.matches_picture_path(name), grey=False)
fig, ax = plt.subplots(figsize=(14, 14 * matches_image.shape[0] / matches_image.shape[1] + 0.6))
ax.imshow(matches_image)
ax.set_title(f"{work.matches_picture_path(name).name}")
ax.set_axis_off()
fig.tight_layout()

# %% [markdown]
# ## 4. The fail-safe: pick correspondences by hand
#
# The picker shows the camera image and the LiDAR image side by side. In JupyterLab, with the
# interactive backend (`%matplotlib widget`, from the `ipympl` package):
#
# - click a point in the **camera image**, then the **same point in the LiDAR image** (or the
#   other way round): a numbered pair, in the same colour in both;
# - pick corners and edges you can find in both: a table corner, a picture frame, a door edge;
#   clicks in the LiDAR image must land on (or within 2 px of) a LiDAR point;
# - **Undo** removes the last click or pair; the toolbar's zoom and pan work as usual (while one
#   is active, clicks navigate instead of picking);
# - 6 to 10 pairs **spread over the image and over near and far things** (3 is the minimum);
# - **Save** writes `WORK/manual_correspondences.json` (or call `picker.save()`).
#
# Run the next cell, click, save, then go on. When the cells run unattended (the test suite,
# "run all"), nobody clicks: the cell after it stands in for you.

# %%
picker = ManualPicker(WORK)
figure = picker.show()  # the figure (with `%matplotlib widget`: clicks go to it)

# %% [markdown]
# ### Standing in for the clicks
#
# With no clicks made, we make them from the ground truth, as a careful person would: pick
# LiDAR-image pixels whose point the camera actually sees (hidden-point removal with the true
# pose, `nbcalib.preprocess.lidar_image.visible_mask`), one in each cell of a 3 x 3 grid over
# the camera image; the camera click is where the true extrinsic projects that point, give or
# take 1 pixel of hand tremor; the LiDAR click is the pixel itself. The clicks go through the
# picker's state (`picker.state`, what the mouse drives), then `picker.save()`.

# %%
T_true = read_ground_truth(GROUND_TRUTH)
simulated = len(picker.state) == 0
rng = np.random.default_rng(0)
if simulated:
    index = pair.lidar_index
    rows, cols = np.nonzero(index >= 0)
    point_ids = index[rows, cols]
    seen = visible_mask(camera, T_true, pair.points_lidar)[point_ids]
    p_camera = pair.points_lidar[point_ids[seen]] @ T_true[:3, :3].T + T_true[:3, 3]
    uv_camera, in_image = camera.project(p_camera, in_image=True)
    lidar_pixels = np.column_stack([cols[seen], rows[seen]])[in_image].astype(float)
    uv_camera, picked_ids = uv_camera[in_image], point_ids[seen][in_image]
    cell = np.floor(uv_camera / [camera.width / 3, camera.height / 3]).astype(int).clip(0, 2)
    chosen = []
    for cell_id in np.unique(cell[:, 1] * 3 + cell[:, 0]):
        members = np.flatnonzero(cell[:, 1] * 3 + cell[:, 0] == cell_id)
        chosen.append(rng.choice(members))
    for k in chosen:
        picker.state.click_camera(*(uv_camera[k] + rng.normal(0.0, 1.0, 2)))
        picker.state.click_lidar(*lidar_pixels[k])
    clicked_ids = picked_ids[chosen]
manual_file = picker.save()
print(picker.state.message)

# %% [markdown]
# A LiDAR click names a point through the index map (the point of the clicked pixel, or of the
# nearest filled pixel within 2 px: `nbcalib.matching.correspondences.lift_lidar_pixels`, as
# `initial-guess` does it). As a check of that lookup, project the named points through the
# virtual camera recorded in `calib.json`: each lands within the search radius of its click
# (inside the clicked pixel, within 0.5 px, for our stand-in clicks on pixel centres).

# %%
picks = picker.state.entries()
lidar_uv = np.array([e.lidar_uv for e in picks])
camera_uv = np.array([e.camera_uv for e in picks])
virtual = get_virtual_camera(work.read_calib())
ids = lift_lidar_pixels(lidar_uv, pair.lidar_index, search_radius=2.0)
p_virtual = pair.points_lidar[ids] @ virtual.T_vcam_lidar[:3, :3].T + virtual.T_vcam_lidar[:3, 3]
uv_virtual, _ = virtual.camera.project(p_virtual)
pixel_gap = np.abs(uv_virtual - lidar_uv).max()
print(f"{len(picks)} picks; the named points project within {pixel_gap:.2f} px of their clicks")

# %% [markdown]
# ### The guess from the picks
#
# `nbcalib initial-guess WORK --manual FILE` reads the file, lifts each LiDAR pixel to its
# point, and runs the same RANSAC + LM as for automatic matches; the result goes to
# `init_T_lidar_camera` (the manual slot of `calib.json`), with each pick's reprojection error
# printed so you can see a bad click.

# %%
manual_status, _ = nbcalib_command("initial-guess", WORK, "--manual", manual_file)
assert manual_status == 0
calib = read_calib_json(WORK / "calib.json")
T_manual = calib.get_T_camera_lidar("init_T_lidar_camera")

# %% [markdown]
# The naive way to the same pose is OpenCV's perspective-n-point solver on the same picks
# (`cv2.solvePnP`: a least-squares fit of the reprojection error). nbcalib's robust fit
# (Cauchy kernel) weighs large errors less, so the two differ slightly.

# %%
ok, rvec, tvec = cv2.solvePnP(
    pair.points_lidar[ids],
    camera_uv,
    camera.K,
    np.zeros(5) if camera.model == "pinhole" else camera.distortion_coeffs,
    flags=cv2.SOLVEPNP_ITERATIVE,
)
T_pnp = np.eye(4)
T_pnp[:3, :3] = cv2.Rodrigues(rvec)[0]
T_pnp[:3, 3] = tvec.ravel()
pnp_vs_package = pose_errors(T_pnp, T_manual)
pnp_cm, pnp_deg = 100 * pnp_vs_package["translation_error_m"], pnp_vs_package["rotation_error_deg"]
print(f"solvePnP and initial-guess --manual differ by {pnp_cm:.2f} cm and {pnp_deg:.3f} deg")

# %% [markdown]
# ## 5. Calibrate, report, evaluate
#
# `nbcalib calibrate WORK` starts from the latest initial guess in `calib.json` (ours, the
# manual one) and minimises the NID (notebook 7); `nbcalib report WORK` writes the quality
# report. In quick mode at most two outer iterations per pyramid level (`--max-outer 2`) and
# one restart in the report (`--restarts 1`).

# %%
nbcalib_command("calibrate", WORK, *(["--max-outer", "2"] if QUICK else []))
report_status, _ = nbcalib_command("report", WORK, *(["--restarts", "1"] if QUICK else []))
calib = read_calib_json(WORK / "calib.json")
T_result = calib.get_T_camera_lidar("T_lidar_camera")
quality = calib.record.quality.figures  # the report's figures, as calib.json keeps them
print(sorted(p.name for p in (WORK / "report").iterdir()))

# %% [markdown]
# The report is `WORK/report/index.html` (open it in a browser). Its figures are files next to
# it; two of them: the points on the image before (the manual guess) and after fine
# registration, coloured by range and by intensity; and the NID along each of the six axes
# around the result (clear valleys: a well-constrained result).

# %%
report_overlay = read_image(WORK / "report" / f"overlay_{name}.png", grey=False)
report_curves = read_image(WORK / "report" / "nid_curves.png", grey=False)
for picture, title in ((report_overlay, "overlays"), (report_curves, "NID curves")):
    h, w = picture.shape[:2]
    fig, ax = plt.subplots(figsize=(12, 12 * h / w + 0.4))
    ax.imshow(picture)
    ax.set_title(f"report: {title}")
    ax.set_axis_off()
    fig.tight_layout()

# %% [markdown]
# With a known answer, `nbcalib evaluate` says how far each stage is from it (one JSON line;
# `--stage` picks the result to judge). Your own recording has none: the report's verdict and
# uncertainty are what you go by.

# %%
evaluation = {}
for stage in ("init_T_lidar_camera", "T_lidar_camera"):
    _, line = nbcalib_command("evaluate", WORK, "--ground-truth", GROUND_TRUTH, "--stage", stage)
    evaluation[stage] = json.loads(line.strip().splitlines()[-1])
guess_cm = 100 * evaluation["init_T_lidar_camera"]["translation_error_m"]
guess_deg = evaluation["init_T_lidar_camera"]["rotation_error_deg"]
final_cm = 100 * evaluation["T_lidar_camera"]["translation_error_m"]
final_deg = evaluation["T_lidar_camera"]["rotation_error_deg"]
better_t, better_r = final_cm < guess_cm, final_deg < guess_deg
refined_better = better_t and better_r
if refined_better:
    change = "brought both the translation and the rotation closer to the truth"
elif better_t or better_r:
    change = f"improved only the {'translation' if better_t else 'rotation'}"
else:
    change = "ended further from the truth than the manual guess"
print(
    f"manual guess {guess_cm:.2f} cm / {guess_deg:.3f} deg -> result {final_cm:.2f} cm / "
    f"{final_deg:.3f} deg: fine registration {change}."
)
u = quality["uncertainty"]
covered = final_cm <= u["translation_total_cm"] and final_deg <= u["rotation_total_deg"]
print(
    f"verdict {quality['verdict']}; stated uncertainty {u['translation_total_cm']:.2f} cm, "
    f"{u['rotation_total_deg']:.3f} deg: the true error is {'inside' if covered else 'OUTSIDE'} it"
)

# %% [markdown]
# Careful hand picks can already be within a centimetre or two and a few tenths of a degree;
# whether fine registration then improves on them is in the sentence above. With a single pair
# it often does not in translation: the NID constrains the rotation far better than the
# translation (docs/BENCHMARKS.md, "Automatic path on synthetic rigs": from good guesses,
# fine registration with one pair often ends further off). Several pairs (several bags, or
# `--pair-count N` on one long bag) constrain it better.

# %% [markdown]
# ## 6. Export
#
# `nbcalib export WORK --format F` writes the result for other tools (`nbcalib export --help`):
# `tf2` (a `static_transform_publisher` command line and a ROS 2 launch file), `urdf` (a fixed
# joint), `opencv` (a YAML file with `K`, `D`, `R`, `t` and `rvec`), or `all`. The ROS outputs
# publish the camera *optical* frame as the child of the LiDAR frame: name your frames with
# `--parent-frame` and `--child-frame`.

# %%
nbcalib_command(
    "export",
    WORK,
    "--format",
    "all",
    "--parent-frame",
    "velodyne",
    "--child-frame",
    "camera_optical",
)
EXPORT = WORK / "export"
exported = sorted(p.name for p in EXPORT.iterdir())
print(exported)

# %% [markdown]
# The tf2 file holds the command that publishes the transform:

# %%
tf2_text = (EXPORT / "tf2_static_transform.sh").read_text()
print(tf2_text)

# %% [markdown]
# The OpenCV file, and a check that it means what it says: `cv2.projectPoints` with its `rvec`,
# `t`, `K` and `D` puts the LiDAR points where the package's camera model puts them with the
# result.

# %%
opencv_text = (EXPORT / "camera_lidar_opencv.yaml").read_text()
print(opencv_text)
storage = cv2.FileStorage(str(EXPORT / "camera_lidar_opencv.yaml"), cv2.FILE_STORAGE_READ)
yaml_K = storage.getNode("camera_matrix").mat()
yaml_D = storage.getNode("distortion_coefficients").mat()
yaml_rvec = storage.getNode("rvec").mat()
yaml_t = storage.getNode("t").mat()
storage.release()

sample = pair.points_lidar[:: max(1, len(pair.points_lidar) // 5000)]
p_result = sample @ T_result[:3, :3].T + T_result[:3, 3]
uv_package, in_view = camera.project(p_result, in_image=True)
uv_cv2 = cv2.projectPoints(sample[in_view], yaml_rvec, yaml_t, yaml_K, yaml_D)[0].reshape(-1, 2)
export_gap_px = float(np.abs(uv_cv2 - uv_package[in_view]).max())
print(f"cv2.projectPoints with the exported YAML vs the package: {export_gap_px:.1e} px")

# %% [markdown]
# ## The payoff: the cloud in the camera's colours
#
# With the extrinsic, every LiDAR point the camera sees takes the colour of its pixel in the
# (colour) image of the bag. In 3-D, seen from beside the camera (pyvista, optional:
# `pip install 'nbcalib[notebooks]'`): the black gaps behind the tables and the pillar are what
# the LiDAR sees but the camera does not (hidden-point removal left them uncoloured).

# %%
rgb = next(read_images(BAG, "/image", grey=False))[1]
seen = visible_mask(camera, T_result, pair.points_lidar)
p_seen = pair.points_lidar[seen] @ T_result[:3, :3].T + T_result[:3, 3]
uv_seen, _ = camera.project(p_seen)
pixel = np.floor(uv_seen + 0.5).astype(int)
colours = rgb[pixel[:, 1], pixel[:, 0]]
print(f"{seen.sum():,} of {len(seen):,} points coloured")

pl = plotter()
colored_view = None
if pl is not None:
    T_lidar_camera = np.linalg.inv(T_result)
    centre, right, forward = T_lidar_camera[:3, 3], T_lidar_camera[:3, 0], T_lidar_camera[:3, 2]
    pl.set_background("black")
    pl.add_points(pair.points_lidar[seen], scalars=colours, rgb=True, point_size=3)
    eye = centre - 2.0 * forward + 1.5 * right + [0.0, 0.0, 1.0]  # behind, right, above
    pl.camera_position = [tuple(eye), tuple(np.median(pair.points_lidar[seen], axis=0)), (0, 0, 1)]
    colored_view = show(pl, "the dense cloud, coloured from the camera image")

# %%
print(f"kept until the next run: {WORK} (open {WORK / 'report' / 'index.html'} in a browser)")

# %% [markdown]
# Next: your own recording. In short:
#
# ```bash
# nbcalib preprocess my.bag work/ --points-topic /lidar --image-topic /camera/image \
#     --camera-info-topic /camera/camera_info
# nbcalib find-matches work/ && nbcalib initial-guess work/
# #   ... when the guess fails: the picker in a notebook, then
# nbcalib initial-guess work/ --manual work/manual_correspondences.json
# nbcalib calibrate work/ && nbcalib report work/
# nbcalib export work/ --format all --parent-frame lidar --child-frame camera_optical_frame
# ```
#
# (or `nbcalib run my.bag work/ ...` for every stage at once). Real recordings are harder than
# this synthetic one: [09_real_data](09_real_data.py) shows what nbcalib currently achieves
# on KITTI and PJLab.

# %% [markdown]
# ## 7. Several cameras around one LiDAR
#
# Robots carry camera rings: a front camera, side fisheyes. `nbcalib synth --cameras` simulates
# one (here a pinhole and a fisheye in front of a Livox, each with its own lens, image size and
# extrinsic), and writes each camera's image and camera info on its own topics. One
# `nbcalib run` calibrates every camera of such a bag: each in its own work directory
# `WORK/<camera>/` (the one-camera layout above), the recording read and each dense cloud made
# once for all; `WORK/rig.json` holds the job and `WORK/report/index.html` a section per camera
# (docs/multi_camera.md).
#
# When the camera-to-camera extrinsics are known (a Kalibr camchain, or nbcalib's rig file,
# `nbcalib.io.rig`), `--rig FILE` refines **one** rig pose from every camera's images at once,
# and each camera's extrinsic is that pose through the rig. `--init` gives the rig's start (the
# first camera's rough `T_lidar_camera`) for when no camera's automatic guess holds; in quick
# mode, with `--no-matching`, it is the start.

# %%
RING = TMP / "ring"
nbcalib_command(
    "synth",
    RING,
    "--format",
    "bag1",
    "--lidar",
    "livox",
    "--cameras",
    "pinhole:640x480,fisheye:512x384",
    "--duration",
    "1" if QUICK else "4",
    "--seed",
    "1",
)
ring_truth = json.loads((RING / "ground_truth.json").read_text())
RING_BAG = next(RING.glob("*.bag"))
ring_topics = package_topics(RING_BAG)
print(sorted(ring_topics))

# %% [markdown]
# The rig file: each camera's model and its pose in the rig's frame (the first camera's). Here
# it is made from the simulation's truth with `nbcalib.io.rig.save_rig`; yours comes from a
# stereo or Kalibr calibration.

# %%
from nbcalib.io.rig import Rig, RigCamera, read_rig, save_rig
from nbcalib.transforms import invert_T, pose_from_xyz_quat, pose_to_xyz_quat, se3_exp

rig_cameras = []
for entry in ring_truth["cameras"]:
    T_cam0_camera = pose_from_xyz_quat(entry["T_cam0_camera"])
    rig_cameras.append(
        RigCamera(
            entry["name"],
            load_camera(RING / entry["name"] / "camera.yaml"),
            invert_T(T_cam0_camera),  # T_camera_cam0
            entry["topics"]["image"],
        )
    )
RIG_FILE = TMP / "rig.yaml"
save_rig(RIG_FILE, Rig(tuple(rig_cameras)))
print(RIG_FILE.read_text())
rig_names = read_rig(RIG_FILE).names()

# %% [markdown]
# A rough start for the rig: the first camera's true extrinsic moved by about 3 cm and a degree.

# %%
T_cam0_true = pose_from_xyz_quat(ring_truth["cameras"][0]["T_lidar_camera"])
rough = T_cam0_true @ se3_exp(np.array([0.02, -0.02, 0.01, 0.01, -0.01, 0.005]))
ROUGH = ",".join(f"{v:.6f}" for v in pose_to_xyz_quat(rough))
ring_start_errors = pose_errors(invert_T(rough), invert_T(T_cam0_true))
print("the start:", ring_start_errors)
RING_WORK = TMP / "ring_work"
quick_ring = ["--no-matching", "--restarts", "1"] if QUICK else []
ring_status, ring_text = nbcalib_command(
    "run", RING_BAG, RING_WORK, "--rig", RIG_FILE, "--init", ROUGH, *quick_ring
)

# %% [markdown]
# `nbcalib evaluate` prints the rig's line (its pose is the first camera's), then one line per
# camera. With the rig given, every camera is off by the same rotation.

# %%
ring_eval_status, ring_eval_text = nbcalib_command(
    "evaluate", RING_WORK, "--ground-truth", RING / "ground_truth.json"
)
ring_lines = [json.loads(line) for line in ring_eval_text.splitlines()]
rig_job = json.loads((RING_WORK / "rig.json").read_text())
print(sorted(p.name for p in RING_WORK.iterdir()))
print("joint rig pose:", rig_job["joint"], "| report:", RING_WORK / "report" / "index.html")

# %% [markdown]
# `nbcalib export RING_WORK` writes every camera in one tree: one tf2 script and launch file
# with a publisher per camera, one URDF with a joint per camera, an OpenCV file per camera.

# %%
nbcalib_command("export", RING_WORK, "--parent-frame", "livox")
ring_urdf = (RING_WORK / "export" / "lidar_cameras.urdf").read_text()
print(ring_urdf)

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - rosbags and nbcalib list the same topics (the bag's four, 5 scans in quick mode);
# - the automatic guess's exit status matches what `calib.json` records of it;
# - the stand-in clicks: at least 6 picks over the 3 x 3 grid, each naming the point clicked,
#   which projects into the clicked pixel;
# - the guess from the picks is within 5 cm / 0.7 degrees of the truth, and within a centimetre
#   and 0.2 degrees of OpenCV's `solvePnP` on the same picks;
# - the result of fine registration is within 5 cm / 0.7 degrees, `evaluate`'s lines are
#   `pose_errors` of `calib.json`'s poses, and the printed sentences (closer or not, inside the
#   stated uncertainty or not) are what the numbers say;
# - the export holds the four files, and `cv2.projectPoints` with the exported YAML agrees with
#   the package's projection to 1e-6 px; the coloured 3-D view is not blank;
# - the camera ring: the bag has both cameras' topics, the run calibrates both (one joint rig
#   pose), `evaluate` prints the rig's line then one per camera, each within 5 cm / 0.7
#   degrees and closer than the start, and the URDF has a joint per camera.
#
# Next: [11_real_recording](11_real_recording.py): a real recording of many frames calibrated
# in one command, with no start given, and the verdict the frames give.
