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
# # 1. Camera models: where does a 3D point land in the image?
#
# Every stage of LiDAR-camera calibration asks one question again and again: *given a point
# in the camera frame, which pixel sees it?* The answer is the camera model. nbcalib has the
# seven models of the reference toolbox, each with its exact Jacobian and its inverse
# (pixel -> ray).
#
# What you will see here:
#
# 1. the frame convention (camera optical frame: x right, y down, z forward);
# 2. how each lens model bends a regular grid of viewing directions;
# 3. that projection and unprojection are inverses, and the Jacobian matches finite
#    differences;
# 4. why the field of view decides between a pinhole and an equirectangular virtual camera.

# %%
import matplotlib.pyplot as plt
import numpy as np

from nbcalib.camera import CAMERA_MODELS, create_camera, example_camera
from nbcalib.reference import camera as reference
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.transforms import transform_points

# %% [markdown]
# ## A camera in five numbers
#
# A pinhole camera maps a point `(x, y, z)` in its optical frame to
# `u = fx * x / z + cx`, `v = fy * y / z + cy`. Pixel centres are at integer coordinates (the
# top-left pixel's centre is `(0, 0)`), as in OpenCV and `docs/conventions.md`.

# %%
cam = create_camera("pinhole", [500.0, 500.0, 319.5, 239.5], [], 640, 480)
points_camera = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [0.0, -0.5, 5.0], [0.0, 0.0, -1.0]])
uv_points, valid_points = cam.project(points_camera)
for p, q, ok in zip(points_camera, uv_points, valid_points):
    print(f"{p} -> {np.round(q, 2)}  valid={ok}")

# %% [markdown]
# The last point is behind the camera: it is *invalid*, never folded onto the image.
#
# ## The formulas by hand, then the kernels
#
# Each model is a few lines of algebra. `nbcalib.reference.camera.project` writes them out
# once more in plain NumPy (the pinhole is the formula above; plumb_bob adds Brown-Conrady's
# radial and tangential terms to `x / z, y / z` before the intrinsics; the fisheye bends the
# angle from the axis instead). nbcalib's numba kernels must give the same pixels for every
# model: here for 2 000 random points in front of each example camera.

# %%
rng = np.random.default_rng(0)
cloud = rng.uniform([-3, -2, 0.5], [3, 2, 8], size=(2000, 3))
by_hand_gap_px = {}  # per model: the largest gap between the reference and the kernel, pixels
for model in CAMERA_MODELS:
    cam = example_camera(model, 640, 480 if model != "equirectangular" else 320)
    uv_kernel, valid = cam.project(cloud)
    uv_hand = reference.project(
        model, cam.intrinsics, cam.distortion_coeffs, cam.width, cam.height, cloud
    )
    by_hand_gap_px[model] = float(np.abs(uv_kernel[valid] - uv_hand[valid]).max())
    print(
        f"{model:20s} {valid.sum():5d} valid points, reference vs kernel "
        f"{by_hand_gap_px[model]:.1e} px"
    )

# %% [markdown]
# ## Seven lenses, one grid of directions
#
# Below, the same set of viewing directions (every 5 degrees within 80 degrees of the optical
# axis) goes through the example lens of each model. Straight lines of directions stay
# straight only for the pinhole camera; radial distortion (plumb_bob, rational_polynomial)
# bends them, and the wide-angle models (fisheye, atan, omnidir) squeeze a large field of view
# into the image. The equirectangular model maps longitude and latitude linearly.

# %%
angles = np.radians(np.arange(-80, 81, 5))
ax_grid, ay_grid = np.meshgrid(angles, angles)
directions = np.stack([np.tan(ax_grid), np.tan(ay_grid), np.ones_like(ax_grid)], axis=-1)
directions = directions.reshape(-1, 3)
directions /= np.linalg.norm(directions, axis=1, keepdims=True)

fov_deg, in_image_fraction, grid_uv = {}, {}, {}  # per model: the titles' numbers, the dots
fig, axes = plt.subplots(2, 4, figsize=(16, 8))
for ax, model in zip(axes.ravel(), CAMERA_MODELS):
    cam = example_camera(model, 640, 480 if model != "equirectangular" else 320)
    uv, valid = cam.project(directions, in_image=True)
    fov_deg[model], in_image_fraction[model] = cam.fov_deg, valid.mean()
    grid_uv[model] = np.where(valid[:, None], uv, np.nan).reshape(*ax_grid.shape, 2)
    ax.scatter(
        uv[valid, 0], uv[valid, 1], s=2, c=np.degrees(ax_grid.ravel()[valid]), cmap="twilight"
    )
    ax.set_xlim(0, cam.width)
    ax.set_ylim(cam.height, 0)
    ax.set_aspect("equal")
    ax.set_title(
        f"{model}\nmodel domain {cam.fov_deg:.0f} deg, {valid.mean():.0%} of rays in image"
    )
axes.ravel()[-1].axis("off")
fig.tight_layout()

# %% [markdown]
# ## One scene through seven lenses
#
# The same room, seen from the same place by each model's example camera: a LiDAR cloud of a
# synthetic room (notebook 2) projected with the rig's true extrinsic and coloured by LiDAR
# intensity. The pinhole kinds see a window of the room; the wide-angle ones most of the half
# space in front; the equirectangular camera the whole sphere, with straight edges turned into
# curves.

# %%
seq = generate_sequence(RigConfig(lidar="spinning64", scene="room", seed=2, duration=0.2))
room, room_intensity = seq.dense_cloud()
room_camera = transform_points(seq.T_camera_lidar, room)
scene_share = {}  # per model: the share of the room's points the camera sees
grey_on_blue = plt.get_cmap("gray").with_extremes(bad="midnightblue")  # blue: no point
fig, axes = plt.subplots(2, 4, figsize=(16, 7))
for ax, model in zip(axes.ravel(), CAMERA_MODELS):
    cam = example_camera(model, 640, 480 if model != "equirectangular" else 320)
    uv, valid = cam.project(room_camera, in_image=True)
    scene_share[model] = valid.mean()
    # each point lights the 2 x 2 pixel cell it lands in (blue: no point there)
    canvas = np.full((cam.height // 2, cam.width // 2), np.nan)
    u, v = (uv[valid] // 2).astype(int).T
    canvas[v, u] = room_intensity[valid]
    ax.imshow(canvas, cmap=grey_on_blue, extent=(0, cam.width, cam.height, 0))
    ax.set_title(f"{model}: {valid.mean():.0%} of the points")
axes.ravel()[-1].axis("off")
fig.tight_layout()

# %% [markdown]
# ## Projection and unprojection are inverses
#
# `unproject` turns a pixel into the unit ray that projects onto it. For every pixel of every
# model, projecting the ray again must give back the pixel. The error is numerical noise.

# %%
round_trip_px, pixels_unprojected = {}, {}  # per model: max error, (pixels with a ray, pixels)
for model in CAMERA_MODELS:
    cam = example_camera(model, 320, 240 if model != "equirectangular" else 160)
    uv = cam.pixel_grid(step=4).astype(float)
    rays = cam.unproject(uv)
    ok = np.all(np.isfinite(rays), axis=1)
    uv_again, valid = cam.project(rays[ok])
    err = np.abs(uv_again - uv[ok])[valid].max()
    round_trip_px[model] = err if valid.all() else np.inf  # a ray that does not project back
    pixels_unprojected[model] = (int(ok.sum()), len(uv))
    print(f"{model:20s} pixels {ok.sum():6d}   max round-trip error {err:.1e} px")

# %% [markdown]
# ## The Jacobian
#
# Fine registration moves the pose by tiny amounts and needs to know how each projection moves
# with it. `project_jacobian` returns `d(u, v) / d(x, y, z)` analytically. A central finite
# difference agrees to within about 1e-7 pixels per metre:

# %%
rng = np.random.default_rng(0)
pts = rng.uniform([-1, -1, 2], [1, 1, 6], (5, 3))
jacobian_error = {}  # per model: max |J - J_fd| over the valid points
for model in CAMERA_MODELS:
    cam = example_camera(model, 640, 480)
    _, J, valid = cam.project_jacobian(pts)
    h = 1e-6
    J_fd = np.stack(
        [(cam.project(pts + h * e)[0] - cam.project(pts - h * e)[0]) / (2 * h) for e in np.eye(3)],
        axis=-1,
    )
    jacobian_error[model] = np.abs(J - J_fd)[valid].max() if valid.all() else np.inf
    print(f"{model:20s} max |J - J_fd| = {jacobian_error[model]:.1e}")

# %% [markdown]
# ## Take-aways
#
# - A point is *valid* only in front of the camera and inside the lens model's monotonic range.
# - Pixel centres are integers; the nearest pixel of `u` is `floor(u + 0.5)`.
# - For LiDAR images nbcalib renders the cloud with a *virtual* camera: a pinhole one when the
#   LiDAR sees less than 150 degrees, an equirectangular one otherwise (notebook 4).
#
# Next: [02_lidar_data](02_lidar_data.py), what a LiDAR gives you and how to read it.

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - the pinhole formula gives the pixels above exactly, and the point behind the camera is
#   invalid;
# - the formulas by hand (`nbcalib.reference.camera`) and the kernels give the same pixels for
#   all seven models;
# - one scene: the wide-angle models see more of the room than the pinhole kinds, the
#   equirectangular camera all of it;
# - every pixel of every model unprojects to a ray that projects back within 3e-13 px;
# - every Jacobian agrees with finite differences within 1e-7;
# - the grid's lines of directions stay straight for the pinhole camera only, and the
#   wide-angle models put more of them in the image.
