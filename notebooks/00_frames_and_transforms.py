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
# # 0. Frames and transforms: which way does `T_camera_lidar` go?
#
# LiDAR-camera calibration estimates one rigid transform, the pose of the camera relative to
# the LiDAR. Half of the problems people have with it are not in the optimisation at all but in
# the bookkeeping: a transform used the wrong way round, a quaternion in the wrong order, a
# camera frame with the wrong axes. This notebook sets the conventions every other notebook uses
# (`docs/conventions.md`):
#
# 1. `T_a_b` maps the coordinates of a point in frame `b` to frame `a`: `p_a = T_a_b @ p_b`;
# 2. composing and inverting, by hand and with `nbcalib.transforms`;
# 3. the LiDAR frame (x forward, y left, z up) against the camera *optical* frame (x right,
#    y down, z forward);
# 4. rotation vectors and the se(3) exponential, against SciPy;
# 5. quaternions `[x, y, z, qx, qy, qz, qw]` as `calib.json` stores `T_lidar_camera`;
# 6. a synthetic rig in 3-D, and LiDAR points projected into its camera: right, and the two
#    classic ways of getting it wrong.

# %%
import json

import matplotlib.pyplot as plt
import numpy as np
from scipy.linalg import logm

from nbcalib.io.calib_json import read_calib_json, write_calib_json
from nbcalib.reference import lie as reference
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.teaching import is_quick, plotter, show, work_folder
from nbcalib.transforms import (
    invert_T,
    make_T,
    matrix_to_quat_xyzw,
    pose_from_xyz_quat,
    pose_to_xyz_quat,
    quat_xyzw_to_matrix,
    random_pose,
    rotation_angle_deg,
    se3_exp,
    se3_log,
    so3_exp,
    so3_log,
    transform_points,
)
from nbcalib.workdir import make_calib

QUICK = is_quick()  # smaller data when the test suite runs the notebooks
np.set_printoptions(precision=4, suppress=True)

# %% [markdown]
# ## `T_a_b`: "a from b"
#
# A rigid transform is a rotation `R` (3 x 3) and a translation `t` (3,), stacked into a 4 x 4
# matrix `[[R, t], [0, 0, 0, 1]]`. With a point written as `[x, y, z, 1]` (homogeneous
# coordinates), applying the transform is one matrix product. The name says which way it goes:
# `T_base_lidar` takes a point measured by the LiDAR (`p_lidar`) to the coordinates of the same
# point in the robot's base frame (`p_base`). Its translation is where the LiDAR's origin is in
# the base frame; its rotation's columns are the LiDAR's axes written in the base frame.
#
# Here the LiDAR sits 1.8 m above the base, turned 90 degrees to the left. A wall point 2 m in
# front of the LiDAR is 2 m to the *left* of the base, 1.8 m up.


# %%
def naive_T(R, t):
    """The 4 x 4 homogeneous matrix [[R, t], [0, 0, 0, 1]]."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def naive_apply(T_a_b, points_b):
    """p_a = T_a_b @ [p_b, 1] for each row of points_b (N, 3)."""
    homogeneous = np.column_stack([points_b, np.ones(len(points_b))])  # (N, 4)
    return (T_a_b @ homogeneous.T).T[:, :3]


yaw = np.radians(90.0)
R_base_lidar = np.array(
    [[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]]
)
T_base_lidar = naive_T(R_base_lidar, [0.0, 0.0, 1.8])
p_lidar = np.array([[2.0, 0.0, 0.0]])  # 2 m in front of the LiDAR
p_base = naive_apply(T_base_lidar, p_lidar)
print("p_lidar", p_lidar[0], "m  ->  p_base", p_base[0], "m")

# %% [markdown]
# ## Composing and inverting
#
# Transforms chain when the *inner* frames match: `T_base_camera = T_base_lidar @ T_lidar_camera`
# (lidar next to lidar). The inverse swaps the names: `T_lidar_base = inv(T_base_lidar)`; for a
# rigid transform it is `[[R.T, -R.T @ t], [0, 1]]`, no general matrix inverse needed.
#
# We compose and invert 200 random poses three ways: the naive 4 x 4 NumPy products and
# `np.linalg.inv`, the closed-form inverse, and `nbcalib.transforms` (`make_T`, `invert_T`,
# `transform_points`). They must agree to rounding error.

# %%
rng = np.random.default_rng(0)
T_ab = random_pose(rng, max_translation=5.0, size=200)  # T_a_b for 200 pose pairs
T_bc = random_pose(rng, max_translation=5.0, size=200)  # T_b_c
points_c = rng.uniform(-10.0, 10.0, size=(50, 3))

compose_gap_m = 0.0  # largest gap between the two ways of taking points from c to a, metres
invert_gap = 0.0  # largest entry of |naive inverse - invert_T|
closed_form_gap = 0.0  # largest entry of |[R.T, -R.T t] - invert_T|
for A, B in zip(T_ab, T_bc):
    T_ac = A @ B  # naive composition, 4 x 4 product
    two_steps = transform_points(A, transform_points(B, points_c))
    compose_gap_m = max(compose_gap_m, np.abs(naive_apply(T_ac, points_c) - two_steps).max())
    invert_gap = max(invert_gap, np.abs(np.linalg.inv(A) - invert_T(A)).max())
    R, t = A[:3, :3], A[:3, 3]
    closed_form = make_T(R.T, -R.T @ t)
    closed_form_gap = max(closed_form_gap, np.abs(closed_form - invert_T(A)).max())
print(f"composition: naive vs nbcalib.transforms, largest gap {compose_gap_m:.1e} m")
print(f"inverse: np.linalg.inv vs invert_T {invert_gap:.1e}, closed form {closed_form_gap:.1e}")

# %% [markdown]
# Composing in the wrong order, `T_bc @ T_ab`, is a valid matrix product but means nothing
# (its inner frames, c and a, do not match): the same points land metres away.

# %%
wrong_order_m = np.median(
    [
        np.linalg.norm(
            transform_points(B @ A, points_c) - transform_points(A @ B, points_c), axis=1
        )
        for A, B in zip(T_ab[:20], T_bc[:20])
    ]
)
print(f"T_bc @ T_ab instead of T_ab @ T_bc: points move by {wrong_order_m:.1f} m (median)")

# %% [markdown]
# ## The LiDAR frame and the camera optical frame
#
# nbcalib's LiDAR frame has the body axes of ROS REP 103: **x forward, y left, z up**. The
# camera frame is the *optical* frame of OpenCV (and of ROS `*_optical_frame`s): **x right,
# y down, z forward**, out of the lens. For a camera that looks straight along the LiDAR's x axis,
# the camera's axes written in LiDAR coordinates are the columns of `R_lidar_camera`:
#
# | camera axis | in the LiDAR frame |
# |---|---|
# | x (right) | -y (to the right of "forward" is minus "left") |
# | y (down) | -z |
# | z (forward) | +x |
#
# So even a camera mounted "without rotation" has a 120-degree rotation in `T_camera_lidar`.

# %%
R_lidar_optical = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
print("R_lidar_camera of a forward-looking camera:\n", R_lidar_optical)
print(f"its rotation angle: {rotation_angle_deg(R_lidar_optical):.1f} deg")
# a point 5 m ahead, 1 m to the left and 0.5 m up of the LiDAR, seen by that camera:
T_lidar_forward_camera = make_T(R_lidar_optical, np.zeros(3))
p_camera_ahead = transform_points(invert_T(T_lidar_forward_camera), [5.0, 1.0, 0.5])
print("LiDAR (5, 1, 0.5) m -> camera", p_camera_ahead, "m: left is -x, up is -y, ahead is +z")

# %% [markdown]
# ## Rotation vectors and the exponential map
#
# The optimiser does not move the nine entries of `R`; it moves a 3-vector `omega` (a rotation
# vector: axis times angle in radians) and maps it to a rotation with the exponential map,
# `R = so3_exp(omega)` (Rodrigues' formula); `so3_log` goes back. A full pose moves along a
# 6-vector `xi = [v, omega]`, **translation first**, through `se3_exp`.
#
# `nbcalib.reference.lie` computes the same maps the textbook way (SciPy's `Rotation` and the
# matrix exponential `expm` of the 4 x 4 twist matrix); the reference has no `se3_log`, so SciPy's
# matrix logarithm `logm` stands in. We compare them on random vectors plus the hard cases: zero,
# a tiny angle, and angles just below 180 degrees.

# %%
n_random = 200
omegas = np.concatenate(
    [
        rng.normal(size=(n_random, 3)),
        [[0.0, 0.0, 0.0], [1e-9, -2e-9, 0.5e-9], [0.0, 0.0, np.pi - 1e-6], [1.0, 1.0, 1.0]],
    ]
)
omegas[-1] *= (np.pi - 1e-4) / np.linalg.norm(omegas[-1])
xis = np.column_stack([rng.normal(size=(len(omegas), 3)), omegas])

so3_exp_gap = max(np.abs(so3_exp(w) - reference.so3_exp(w)).max() for w in omegas)
so3_log_gap = max(
    np.abs(so3_log(reference.so3_exp(w)) - reference.so3_log(reference.so3_exp(w))).max()
    for w in omegas
)
se3_exp_gap = max(np.abs(se3_exp(x) - reference.se3_exp(x)).max() for x in xis)


def naive_se3_log(T):
    """[v, omega] of T from SciPy's matrix logarithm of the 4 x 4 matrix."""
    X = np.real(logm(T))
    return np.array([X[0, 3], X[1, 3], X[2, 3], X[2, 1], X[0, 2], X[1, 0]])


se3_log_gap = max(
    np.abs(se3_log(reference.se3_exp(x)) - naive_se3_log(se3_exp(x))).max() for x in xis
)
print(f"so3_exp vs SciPy {so3_exp_gap:.1e}, so3_log vs SciPy {so3_log_gap:.1e} rad")
print(f"se3_exp vs expm {se3_exp_gap:.1e}, se3_log vs logm {se3_log_gap:.1e}")

# %% [markdown]
# The se(3) exponential is *not* "rotation vector plus translation": `se3_exp([v, omega])` has the
# translation `V(omega) @ v`, not `v`. The pose `se3_exp(s * xi)` for `s` from 0 to 1 moves
# along a screw, so its origin follows an arc, as a wheel turning while it rolls:

# %%
xi_turn = np.array([2.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2])  # 2 m forward while turning 90 deg left
path = np.array([se3_exp(s * xi_turn)[:3, 3] for s in np.linspace(0.0, 1.0, 30)])
end_of_screw = path[-1]
print(f"se3_exp end point {end_of_screw[:2]} m; the shortcut would put it at {xi_turn[:2]} m")

fig, ax = plt.subplots(figsize=(5, 4.5))
ax.plot(path[:, 0], path[:, 1], "o-", ms=3, label="origin of se3_exp(s xi), s = 0..1")
ax.plot([0, xi_turn[0]], [0, xi_turn[1]], "k--", label="shortcut: t = v")
for s_index in (0, 10, 20, 29):
    R = se3_exp(np.linspace(0.0, 1.0, 30)[s_index] * xi_turn)[:3, :3]
    ax.arrow(*path[s_index, :2], *(0.3 * R[:2, 0]), width=0.01, color="r")
ax.set_aspect("equal")
ax.set_xlabel("x [m]")
ax.set_ylabel("y [m]")
ax.set_title("xi = [2, 0, 0, 0, 0, pi/2]: red arrows = the x axis")
ax.legend(loc="upper left", fontsize=8)
fig.tight_layout()

# %% [markdown]
# ## Quaternions and `calib.json`
#
# Files store a rotation as a unit quaternion. nbcalib, ROS and the reference toolbox's
# `calib.json` all write it **xyzw** (scalar last); Eigen's constructor and many papers take
# wxyz, a classic source of nonsense poses. A quaternion and its negative are the same rotation,
# so compare rotations, never raw quaternions.
#
# We first build a synthetic rig (a 64-beam LiDAR in a room and a pinhole camera, its true
# extrinsic drawn like a real rig's: 5-30 cm away, looking anywhere).

# %%
config = RigConfig(
    lidar="spinning64",
    camera="pinhole",
    scene="room",
    seed=5,
    motion="static",
    duration=0.1,  # one revolution of the LiDAR
    image_size=(640, 480) if QUICK else (1280, 960),
)
seq = generate_sequence(config)
T_camera_lidar = seq.T_camera_lidar  # the answer: p_camera = T_camera_lidar @ p_lidar
T_lidar_camera = invert_T(T_camera_lidar)  # the camera's pose in the LiDAR frame
print("T_camera_lidar =\n", T_camera_lidar)

# %% [markdown]
# `matrix_to_quat_xyzw` gives the quaternion of a rotation (with `qw >= 0`), `pose_to_xyz_quat`
# the seven numbers `[x, y, z, qx, qy, qz, qw]` of a 4 x 4 transform, `pose_from_xyz_quat` goes
# back. SciPy (through the reference) gives the same quaternion, and `-q` the same matrix.
#
# A reader that expects the scalar first (wxyz, as Eigen's `Quaterniond(w, x, y, z)`) takes
# `qx` for `w`, `qy` for `x`, and so on: a different, valid-looking rotation.

# %%
q_xyzw = matrix_to_quat_xyzw(T_lidar_camera[:3, :3])
xyz_quat = pose_to_xyz_quat(T_lidar_camera)
print("T_lidar_camera as [x, y, z, qx, qy, qz, qw]:", xyz_quat)
quat_gap = np.abs(q_xyzw - reference.matrix_to_quat(T_lidar_camera[:3, :3])).max()
minus_q_gap = np.abs(quat_xyzw_to_matrix(-q_xyzw) - T_lidar_camera[:3, :3]).max()
round_trip_gap = np.abs(pose_from_xyz_quat(xyz_quat) - T_lidar_camera).max()
print(f"vs SciPy {quat_gap:.1e}; R(-q) vs R {minus_q_gap:.1e}; round trip {round_trip_gap:.1e}")
qx, qy, qz, qw = q_xyzw
T_lidar_camera_wxyz = pose_from_xyz_quat([*xyz_quat[:3], qy, qz, qw, qx])  # read as w, x, y, z
wxyz_mistake_deg = rotation_angle_deg(T_lidar_camera_wxyz[:3, :3] @ T_lidar_camera[:3, :3].T)
print(f"read as wxyz by mistake, the rotation is {wxyz_mistake_deg:.0f} deg off")

# %% [markdown]
# `calib.json` (the reference toolbox's file, which nbcalib reads and writes) stores
# **`T_lidar_camera`**, the inverse of the `T_camera_lidar` every computation uses. Its first
# three numbers are therefore the camera's position in the LiDAR frame, the distance you would
# measure with a ruler. `nbcalib.io.calib_json` is the only place where the direction changes:
# `CalibFile.set_T_camera_lidar` writes the inverse, `get_T_camera_lidar` reads it back.

# %%
work = work_folder("00_frames_and_transforms").resolve()  # work/00_... here, emptied
calib = make_calib(seq.camera, ["pair_000"])  # a fresh calib.json, as nbcalib preprocess makes
calib.set_T_camera_lidar("T_lidar_camera", T_camera_lidar)
write_calib_json(work / "calib.json", calib)
stored = json.loads((work / "calib.json").read_text())["results"]["T_lidar_camera"]
print("calib.json results.T_lidar_camera:", np.round(stored, 4))
T_camera_lidar_read = read_calib_json(work / "calib.json").get_T_camera_lidar("T_lidar_camera")
calib_gap = np.abs(T_camera_lidar_read - T_camera_lidar).max()
camera_distance_m = float(np.linalg.norm(stored[:3]))
print(f"read back as T_camera_lidar: largest gap {calib_gap:.1e}")
print(f"the camera is {100 * camera_distance_m:.1f} cm from the LiDAR")
print(
    f"(the translation of T_camera_lidar, {np.round(T_camera_lidar[:3, 3], 4)} m, is the LiDAR "
    "origin in camera coordinates, not a distance you can measure as easily)"
)

# %% [markdown]
# ## The rig in 3-D
#
# The LiDAR's axes (red x, green y, blue z, 1 m long) at the origin, the camera's axes (0.5 m,
# same colours) at `T_lidar_camera`, its viewing frustum (orange: the image corners unprojected
# to 1.5 m, then taken into the LiDAR frame with `T_lidar_camera`), and the room as one LiDAR
# revolution sees it, coloured by height (the ceiling left out, so that we can look in). The
# camera's blue z axis points along the middle of its frustum, its green y axis down.

# %%
points, intensities = seq.dense_cloud()  # one revolution, in the LiDAR frame
width, height = seq.camera.width, seq.camera.height
corners_uv = np.array(
    [[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]]
)
corner_rays = seq.camera.unproject(corners_uv)  # unit bearings in the camera frame


def frustum(depth):
    """Camera centre and the 4 image corners at ``depth`` metres, in the LiDAR frame (5, 3)."""
    corners_camera = depth * corner_rays / corner_rays[:, 2:]
    return transform_points(T_lidar_camera, np.vstack([np.zeros(3), corners_camera]))


edges = [(0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1)]
camera_centre = T_lidar_camera[:3, 3]
axes_lidar = np.eye(3)
axes_camera = T_lidar_camera[:3, :3].T  # rows: the camera's x, y, z axes in the LiDAR frame
below_ceiling = points[:, 2] < np.percentile(points[:, 2], 90)

pl = plotter()
image_3d = None  # the rendered view (None when it opened interactively)
if pl is not None:
    import pyvista as pv

    cloud = pv.PolyData(points[below_ceiling][:: 2 if QUICK else 1])
    cloud["height [m]"] = cloud.points[:, 2]
    pl.add_points(
        cloud,
        scalars="height [m]",
        cmap="viridis",
        point_size=2,
        scalar_bar_args={"title": "height [m]", "vertical": True, "fmt": "%.1f"},
    )
    for k, colour in enumerate(("red", "green", "blue")):
        pl.add_mesh(pv.Arrow(start=(0, 0, 0), direction=axes_lidar[k], scale=1.0), color=colour)
        pl.add_mesh(
            pv.Arrow(start=camera_centre, direction=axes_camera[k], scale=0.5), color=colour
        )
    corners = frustum(1.5)
    for a, b in edges:
        pl.add_mesh(pv.Line(corners[a], corners[b]), color="orange", line_width=3)
    pl.add_point_labels(
        np.array([[0.0, 0.0, 1.1], camera_centre + 0.6 * axes_camera[2]]),
        ["LiDAR", "camera"],
        font_size=14,
        point_size=1,
        shape_opacity=0.5,
    )
    pl.camera_position = [(-6.0, -9.0, 7.0), (0.5, 0.5, 0.0), (0.0, 0.0, 1.0)]
    image_3d = show(pl, "LiDAR axes (1 m), camera axes (0.5 m) and frustum (orange), the room")

# %% [markdown]
# The same with matplotlib (always available), and a close-up of the rig: the two triads differ
# by the optical-frame rotation of the table above plus the camera's own yaw, pitch and roll.

# %%
fig = plt.figure(figsize=(15, 7))
sample = points[below_ceiling][:: 4 if QUICK else 2]
ax = fig.add_subplot(1, 2, 1, projection="3d")
ax.scatter(*sample.T, s=0.5, c=sample[:, 2], cmap="viridis", alpha=0.8, depthshade=False)
for k, colour in enumerate(("r", "g", "b")):
    ax.quiver(0, 0, 0, *axes_lidar[k], color=colour, linewidth=2)
    ax.quiver(*camera_centre, *(0.5 * axes_camera[k]), color=colour, linewidth=2)
for a, b in edges:
    ax.plot(*frustum(1.5)[[a, b]].T, color="orange")
ax.set_box_aspect(np.ptp(sample, axis=0))
ax.view_init(elev=40, azim=-125)
ax.set_title("the room, the LiDAR and the camera (orange: frustum)")

ax = fig.add_subplot(1, 2, 2, projection="3d")
for k, (colour, name) in enumerate(zip("rgb", "xyz")):
    ax.quiver(0, 0, 0, *(0.3 * axes_lidar[k]), color=colour, linewidth=2)
    ax.text(*(0.34 * axes_lidar[k]), f"LiDAR {name}", color=colour)
    ax.quiver(*camera_centre, *(0.2 * axes_camera[k]), color=colour, linewidth=2, linestyle="--")
    ax.text(*(camera_centre + 0.23 * axes_camera[k]), f"camera {name}", color=colour)
for a, b in edges:
    ax.plot(*frustum(0.3)[[a, b]].T, color="orange")
ax.set_xlim(-0.4, 0.4)
ax.set_ylim(-0.4, 0.4)
ax.set_zlim(-0.4, 0.4)
ax.set_box_aspect((1, 1, 1))
ax.view_init(elev=20, azim=-55)
ax.set_title("close-up: solid = LiDAR axes, dashed = camera axes")
for ax in fig.axes:
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
fig.tight_layout()

# %% [markdown]
# ## LiDAR points in the camera image
#
# Projection is two steps: `p_camera = T_camera_lidar @ p_lidar`, then the camera model. For a
# pinhole camera the model is `u = fx x / z + cx`, `v = fy y / z + cy` for points in front
# (`z > 0`). We do it by hand, then with `transform_points` and `camera.project`; they agree.

# %%
fx, fy, cx, cy = seq.camera.intrinsics
p_cam = naive_apply(T_camera_lidar, points)
ahead = p_cam[:, 2] > 0
uv_naive = np.column_stack(
    [fx * p_cam[:, 0] / p_cam[:, 2] + cx, fy * p_cam[:, 1] / p_cam[:, 2] + cy]
)
in_view_naive = (
    ahead
    & (uv_naive[:, 0] >= -0.5)
    & (uv_naive[:, 0] < seq.camera.width - 0.5)
    & (uv_naive[:, 1] >= -0.5)
    & (uv_naive[:, 1] < seq.camera.height - 0.5)
)
uv, valid = seq.camera.project(transform_points(T_camera_lidar, points), in_image=True)
projection_gap_px = np.abs(uv[valid] - uv_naive[valid]).max()
print(f"{valid.sum():,} of {len(points):,} points in the image; by hand: {in_view_naive.sum():,}")
print(f"largest gap between the two projections: {projection_gap_px:.1e} px")

# %% [markdown]
# How do we know the overlay is right, beyond "it looks right"? The synthetic rig records,
# for every LiDAR point, the scene primitive (wall, box, poster...) it hit, and for every pixel
# the primitive the camera saw. A correct projection puts each point on a pixel of its own
# primitive (apart from points hidden from the camera and points on edges).

# %%
prim = np.concatenate([scan.prim for scan in seq.scans])


def same_surface(uv, valid):
    """Fraction of the projected points that land on a pixel showing their own primitive."""
    if not valid.any():
        return 0.0
    col, row = np.floor(uv[valid] + 0.5).astype(int).T
    return float(np.mean(prim[valid] == seq.rendered.prim[row, col]))


overlays = {"T_camera_lidar (right)": (uv, valid)}
print(f"right: {100 * same_surface(uv, valid):.1f} % of the points on their own surface")

# %% [markdown]
# ## What went wrong? Three pictures to recognise
#
# 1. **The inverse**: `T_lidar_camera` (the direction `calib.json` stores) used where
#    `T_camera_lidar` belongs. The rotation is applied backwards, so the points come from another
#    part of the room: plenty of them land in the image, on the wrong things.
# 2. **The quaternion read wxyz**: the same kind of picture, another part of the room (here
#    the rotation is 58 degrees off).
# 3. **Body axes for the optical axes**: a camera pose written in body axes (x forward, y left,
#    z up, as a ROS `camera_link`) used as if it were the optical frame (`camera_optical_frame`).
#    The camera model then looks along the camera's *up*: above a spinning LiDAR's +-22.5 degree
#    field of view there is nothing, and the image stays empty (or only the top of a tall
#    object appears, far from where it belongs).
#
# Coloured by range, the right overlay follows the image's edges; the wrong ones cut across them.

# %%
T_body_optical = make_T(R_lidar_optical, np.zeros(3))  # optical axes -> body axes
T_mistake_axes = T_body_optical @ T_camera_lidar  # "camera_link" (body axes) <- lidar
for label, T in (
    ("T_lidar_camera (the inverse)", T_lidar_camera),
    ("quaternion read as wxyz", invert_T(T_lidar_camera_wxyz)),
    ("body axes taken for optical", T_mistake_axes),
):
    overlays[label] = seq.camera.project(transform_points(T, points), in_image=True)
    share = same_surface(*overlays[label])
    print(
        f"{label}: {overlays[label][1].sum():,} points in the image, {100 * share:.1f} % "
        "on their own surface"
    )
same_surface_share = {label: same_surface(*o) for label, o in overlays.items()}

fig, axes = plt.subplots(2, 2, figsize=(14, 10), layout="constrained")
depth = np.linalg.norm(points, axis=1)
dots = None
for ax, (label, (uv_k, valid_k)) in zip(axes.ravel(), overlays.items()):
    ax.imshow(seq.image, cmap="gray")
    dots = ax.scatter(
        uv_k[valid_k, 0],
        uv_k[valid_k, 1],
        s=0.4,
        c=depth[valid_k],
        cmap="turbo",
        vmin=1.0,
        vmax=5.0,
        alpha=0.7,
    )
    ax.set_title(
        f"{label}\n{valid_k.sum():,} points in the image, "
        f"{100 * same_surface_share[label]:.0f} % on their own surface"
    )
    ax.set_axis_off()
fig.suptitle("LiDAR points coloured by range over the camera image")
colorbar = fig.colorbar(dots, ax=axes, shrink=0.6, label="range from the LiDAR [m]")

# %% [markdown]
# ## Take-aways
#
# - Read `T_a_b` as "a from b": `p_a = T_a_b @ p_b`; chain only matching inner frames.
# - nbcalib optimises `T_camera_lidar` (LiDAR points into the camera); `calib.json` stores its
#   inverse `T_lidar_camera` as `[x, y, z, qx, qy, qz, qw]`, xyzw.
# - The camera frame is the optical frame: x right, y down, z forward.
# - If an overlay shows a different part of the scene, try the inverse and the quaternion
#   order; if it is (nearly) empty, check the optical-frame axes.
#
# Next: [01_camera_models](01_camera_models.py), what the camera model does with a point in the
# camera frame.

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - the point 2 m ahead of the turned LiDAR is 2 m to the left of the base, 1.8 m up;
# - naive 4 x 4 composition and inversion agree with `nbcalib.transforms` to 1e-12, and the
#   wrong order moves points by metres;
# - a forward-looking camera's `R_lidar_camera` maps LiDAR forward/left/up to camera
#   z/-x/-y, a 120-degree rotation;
# - `so3_exp`, `so3_log`, `se3_exp` and `se3_log` agree with SciPy to 1e-9, and the screw's end
#   point is not the shortcut's;
# - the quaternion is xyzw and SciPy's, `-q` is the same rotation, wxyz is a different one;
# - `calib.json` stores the inverse of `T_camera_lidar` and reads back to it exactly; its
#   translation is the camera's 5-30 cm offset;
# - the 3-D view is not blank (where pyvista renders) and the matplotlib figures are there;
# - the hand-made pinhole projection equals `camera.project`; the right overlay puts more than
#   95 % of the points on their own surface, the inverse and the wxyz quaternion less than
#   20 %, and the body-axes mistake puts (almost) nothing in the image.
