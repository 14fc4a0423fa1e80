# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 2. A synthetic rig: a calibration problem with a known answer
#
# Real data rarely comes with the true extrinsic, so you cannot tell a 2 cm error from a
# 20 cm one. nbcalib's synthetic rig ray-casts a procedural room or street with a simulated
# LiDAR (spinning or Livox-like rosette, with motion distortion and noise) and renders the
# camera image through any of the seven camera models. The answer, `T_camera_lidar`, is known.
#
# The LiDAR's reflectivity and the camera's albedo are *correlated but not equal*: the
# cross-modal gap every real calibration has to bridge.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.transforms import transform_points

# Smaller data when the test suite runs the notebooks.
QUICK = os.environ.get("NBCALIB_NOTEBOOK_QUICK") == "1"

# %% [markdown]
# ## One pair
#
# A 64-beam spinning LiDAR nods in a room for one second (ten 0.1 s scans) while a plumb_bob
# camera takes one image at the start of the first scan. The seed fixes everything.

# %%
config = RigConfig(
    lidar="spinning64",
    camera="plumb_bob",
    scene="room",
    seed=3,
    duration=0.3 if QUICK else 1.0,
    image_size=(640, 480) if QUICK else (1280, 960),
)
seq = generate_sequence(config)
print(f"{len(seq.scans)} scans, {sum(len(s) for s in seq.scans):,} points, image {seq.image.shape}")
print("ground truth T_camera_lidar:\n", np.round(seq.T_camera_lidar, 4))

# %% [markdown]
# ## The camera image and one LiDAR scan
#
# The image is grey with shading and shadows. A single scan of a 64-beam LiDAR is sparse:
# 64 rings with large gaps between them, which is why the method first accumulates a *dense*
# cloud (notebook 3).

# %%
scan = seq.scans[0]
fig, axes = plt.subplots(1, 2, figsize=(15, 5))
axes[0].imshow(seq.image, cmap="gray")
axes[0].set_title("camera image")
top = scan.points[:, 2] < 3.0
axes[1].scatter(
    scan.points[top, 0], scan.points[top, 1], s=0.2, c=scan.intensities[top], cmap="gray"
)
axes[1].set_aspect("equal")
axes[1].set_title("scan 0 seen from above (x forward, y left), coloured by intensity")
fig.tight_layout()

# %% [markdown]
# ## The same points through the true extrinsic
#
# `p_camera = T_camera_lidar @ p_lidar`, then the camera model. With the true pose, the LiDAR
# points coloured by range line up with the image's edges. Here we use the points deskewed
# with the true trajectory (`seq.dense_cloud()`), so motion distortion plays no part yet.

# %%
points, intensities = seq.dense_cloud()
uv, valid = seq.camera.project(transform_points(seq.T_camera_lidar, points), in_image=True)
depth = np.linalg.norm(points[valid], axis=1)

fig, ax = plt.subplots(figsize=(10, 7.5))
ax.imshow(seq.image, cmap="gray")
ax.scatter(uv[valid, 0], uv[valid, 1], s=0.3, c=depth, cmap="turbo", alpha=0.6)
ax.set_title(f"{valid.sum():,} LiDAR points projected with the true T_camera_lidar")
ax.set_axis_off()

# %% [markdown]
# ## In 3D
#
# pyvista shows the dense cloud interactively in JupyterLab (`pip install nbcalib[notebooks]`);
# without a display it renders a static picture.

# %%
try:
    import pyvista as pv

    cloud = pv.PolyData(points[:: 1 if not QUICK else 10])
    cloud["intensity"] = intensities[:: 1 if not QUICK else 10]
    plotter = pv.Plotter(off_screen=QUICK)
    plotter.add_points(cloud, scalars="intensity", cmap="gray", point_size=2)
    plotter.add_axes()
    if QUICK:
        plotter.screenshot(None)
    else:
        plotter.show()
except ImportError:
    print("pyvista is not installed: pip install 'nbcalib[notebooks]'")

# %% [markdown]
# ## From the command line
#
# `nbcalib synth OUT --lidar spinning64 --camera plumb_bob --pairs 1 --seed 3` writes the same
# kind of pair as PCD files, a PNG and `camera.yaml` (or as a ROS1/ROS2/mcap bag with
# `--format`), plus `ground_truth.json` for `nbcalib evaluate`.
#
# Next: [03_dense_clouds](03_dense_clouds.py), turning sparse moving scans into one dense cloud.

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - the ground truth is the extrinsic the rig was built with (`default_T_camera_lidar`), 5-30 cm
#   from the LiDAR;
# - one 0.1 s scan per 0.1 s of data, each of 64 rings, with per-point times in order;
# - the points projected with the true extrinsic land on the surface the camera saw at that
#   pixel (`seq.rendered`): the same primitive, a centimetre or so away.
