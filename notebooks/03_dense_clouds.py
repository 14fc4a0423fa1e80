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
# # 3. Dense point clouds: accumulate, and undo the motion
#
# One scan of a spinning LiDAR is too sparse to show the texture a camera sees; the method
# (paper section III-C) therefore accumulates several scans into one dense cloud in the LiDAR
# frame at the start of the first scan, which is when the camera image was taken.
#
# - A **non-repetitive** LiDAR (Livox) held still fills its field of view by itself: *static
#   integration* stacks the scans and removes duplicates on a voxel grid.
# - A **spinning** LiDAR must move to fill the gaps between its rings, and then each point was
#   measured from a different pose. *Dynamic integration* estimates, with continuous-time ICP,
#   the pose at the beginning and at the end of every scan, interpolates a pose for each point
#   from its timestamp, and moves the point back to where it belongs (*deskewing*).
#
# We use a synthetic nodding sequence, so the true trajectory is known.

# %%
import matplotlib.pyplot as plt
import numpy as np

from nbcalib.odometry import integrate_dynamic, local_thickness
from nbcalib.odometry.deskew import deskew
from nbcalib.preprocess.accumulate import integrate_static
from nbcalib.reference import integrate as reference
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.teaching import is_quick, plotter, show
from nbcalib.transforms import invert_T, pose_error

QUICK = is_quick()  # small data when the test suite runs the notebook

# %%
seq = generate_sequence(
    RigConfig(
        lidar="spinning64", scene="room", motion="nod", seed=1, duration=0.5 if QUICK else 2.0
    )
)
scans = [np.column_stack([s.points, s.intensities]) for s in seq.scans]
times = [s.times for s in seq.scans]
print(f"{len(scans)} scans of ~{len(scans[0]):,} points, per-point times over 0.1 s each")

# %% [markdown]
# ## Naive: stack the scans as if nothing moved
#
# `integrate_static` is right for a LiDAR at rest. On a nodding sensor it smears every surface.

# %%
naive = integrate_static(scans)

# %% [markdown]
# ## Continuous-time ICP
#
# Each new scan is registered to a local voxel map of the scans before it, estimating its begin
# and end poses; a constant-velocity model predicts the next scan. Per-point poses are
# interpolated between begin and end.

# %%
dense = integrate_dynamic(scans, times)
print(f"naive cloud {len(naive):,} points, deskewed cloud {len(dense):,} points")

# %% [markdown]
# ### How good is the estimated trajectory?
#
# Compare each scan's estimated end pose with the truth (both relative to the LiDAR pose at the
# start of the first scan).

# %%
T_first_world = invert_T(seq.T_world_lidar(seq.scans[0].stamp + times[0].min()))
t_end = np.array([s.stamp + t.max() for s, t in zip(seq.scans, times)])
T_end_true = T_first_world @ seq.T_world_lidar(t_end)
trans_err, rot_err = pose_error(dense.T_first_scanend, T_end_true)
for k, (te, re) in enumerate(zip(trans_err, rot_err)):
    print(f"scan {k:2d}: {100 * te:5.2f} cm  {re:5.3f} deg")

# %% [markdown]
# ### Deskewing, by hand
#
# Deskewing itself is short. A point measured at normalised time `s` in [0, 1] of its scan was
# seen from the pose `T(s)` that slerps the rotation and lerps the translation between the
# scan's begin and end poses; `p_first = T(s) p`. The slow reference
# (`nbcalib.reference.integrate.deskew`) does it one point at a time, exactly as written; the
# numba kernel behind `nbcalib.odometry.deskew` must give the same points. Here with the
# estimated poses of the last scan.

# %%
k = len(scans) - 1
t = times[k]
s = (t - t.min()) / (t.max() - t.min())
every = slice(None, None, 20)  # the reference is slow: one point in 20
T_begin, T_end = dense.T_first_scanbegin[k], dense.T_first_scanend[k]
by_hand = reference.deskew(scans[k][every, :3], s[every], T_begin, T_end)
by_kernel = deskew(scans[k][every, :3], s[every], T_begin, T_end)
deskew_gap = np.abs(by_hand - by_kernel).max()  # metres
moved = np.linalg.norm(by_kernel - scans[k][every, :3], axis=1)
print(f"reference vs kernel: {deskew_gap:.1e} m apart at most, over {len(s[every]):,} points")
print(f"into the frame of the first scan, scan {k} moved {100 * np.median(moved):.1f} cm (median)")

# %% [markdown]
# ### Sharper surfaces
#
# `local_thickness` fits planes to neighbourhoods of 50 points and reports the median spread
# along their normals: motion blur makes surfaces thick. The deskewed cloud should be about as
# thin as the cloud deskewed with the *true* trajectory (what is left is the LiDAR's range
# noise); the naive one thicker. (With small neighbourhoods, the naive cloud's neighbours often
# come from one scan alone, which is sharp by itself: use enough neighbours to mix scans.)

# %%
truth_points, _ = seq.dense_cloud()
thickness = {}  # median local thickness of each cloud, metres
for label, points in (
    ("naive (no motion model)", naive.points),
    ("continuous-time ICP", dense.points),
    ("true trajectory", truth_points),
):
    thickness[label] = local_thickness(points, k=50)
    print(f"{label:26s} median local thickness {1e3 * thickness[label]:.1f} mm")

# %% [markdown]
# ## Look at a slice
#
# A horizontal slice 1.0-1.2 m above the LiDAR, seen from above: the walls of the room are thin
# lines after deskewing and blurred bands without it.

# %%
fig, axes = plt.subplots(1, 2, figsize=(14, 6), sharex=True, sharey=True)
for ax, (label, cloud) in zip(axes, (("naive", naive), ("deskewed", dense))):
    z = cloud.points[:, 2]
    band = (z > 1.0) & (z < 1.2)
    ax.scatter(cloud.points[band, 0], cloud.points[band, 1], s=0.1, c="k")
    ax.set_aspect("equal")
    ax.set_title(f"{label}: slice z in [1.0, 1.2] m")
fig.tight_layout()

# %% [markdown]
# ## Before and after, in 3-D
#
# The same two clouds side by side (drag to turn them in JupyterLab; a still image elsewhere),
# without floor and ceiling, seen from above and coloured by height: the naive cloud's walls
# and furniture are doubled and blurred, the deskewed ones single and thin.

# %%
pl = plotter(window_size=(1200, 500), shape=(1, 2))
views = None  # the rendered image, where the view is rendered off screen
if pl is not None:
    for column, (label, cloud) in enumerate((("naive", naive), ("deskewed", dense))):
        pl.subplot(0, column)
        z = cloud.points[:, 2]
        inside = (z > -0.8) & (z < 1.5)  # above the floor, below the ceiling
        pl.add_points(
            cloud.points[inside],
            scalars=z[inside],
            clim=(-0.8, 1.5),
            cmap="viridis",
            point_size=1,
            show_scalar_bar=column == 1,
            scalar_bar_args={"title": "height z [m]"},
        )
        pl.add_text(label, font_size=12)
        pl.view_xy()
    pl.link_views()
    views = show(pl, "naive vs deskewed, seen from above")

# %% [markdown]
# ## On your own data
#
# ```bash
# nbcalib preprocess scans/*.pcd image.png work --camera camera.yaml          # auto mode
# nbcalib preprocess recording.bag work --dynamic                              # force CT-ICP
# ```
#
# `auto` chooses dynamic integration when there are at least two scans covering more than 180
# degrees of azimuth (a spinning LiDAR), static otherwise. KITTI `.bin` files carry no per-point
# time: nbcalib synthesises it from each point's azimuth and `--frame-rate`.
#
# Next: [04_virtual_camera](04_virtual_camera.py), rendering the dense cloud as an image.

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - the continuous-time ICP trajectory stays within 3 cm and 0.6 degrees of the truth;
# - deskewing by hand (the reference) and with the kernel give the same points;
# - the deskewed cloud is within 10 % of the thickness of the truly deskewed one, and the naive
#   cloud at least 25 % thicker;
# - the 3-D view rendered (where pyvista is installed).
