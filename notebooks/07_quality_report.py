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
# # 7. Is the result right? The whole pipeline from Python, and the quality report
#
# Users of the reference toolbox say it: "we can only check with our eyes". nbcalib checks for
# you, and shows you what it checked:
#
# - **the NID along each axis** around the result: a clear minimum on all six axes, or a flat
#   direction the data does not constrain;
# - **an uncertainty** in centimetres and degrees, from the curvature of the cost at the
#   optimum (scaled on synthetic pairs with known answers);
# - **a verdict**, `ok` or `suspect`, with reasons: too few points in view, a flat cost, a
#   result far from the initial guess, pairs that disagree, an optimiser that did not converge.
#
# Here the whole pipeline runs from Python on a synthetic pair, once from a good start and once
# with a wrong image, to see the verdict change.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

import nbcalib
from nbcalib.metrics import pose_errors
from nbcalib.report.quality import AXIS_NAMES
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.transforms import se3_exp

QUICK = os.environ.get("NBCALIB_NOTEBOOK_QUICK") == "1"

# %% [markdown]
# ## Calibrate in one call
#
# `nbcalib.calibrate` takes points, intensities, an image and a camera (arrays or file
# paths), runs every stage and returns the pose, the intermediate products and the quality
# figures. Here we give it a start pose 5 cm / 1 degree off the truth (`T_init`); without one
# it finds its own by keypoint matching (notebook 5).

# %%
seq = generate_sequence(
    RigConfig(
        lidar="livox",
        camera="pinhole",
        scene="room",
        seed=0,
        duration=0.5 if QUICK else 1.0,
        image_size=(640, 480),
    )
)
points, intensities = seq.dense_cloud()
delta = np.array([0.03, -0.03, 0.028, 0.01, -0.01, 0.0101])  # ~5 cm, ~1 degree
T_start = se3_exp(delta) @ seq.T_camera_lidar

result = nbcalib.calibrate(
    points, intensities, seq.image, seq.camera, T_init=T_start, max_outer=3 if QUICK else 10
)
start_error = pose_errors(T_start, seq.T_camera_lidar)
print("start :", start_error)
print("result:", pose_errors(result.T_camera_lidar, seq.T_camera_lidar))

# %% [markdown]
# ## What the quality check says

# %%
q = result.quality
print("verdict:", q.verdict, q.reasons)
u = q.uncertainty
print(
    f"{100 * u['confidence']:.0f} % bounds: translation <= {u['translation_total_cm']:.2f} cm, "
    f"rotation <= {u['rotation_total_deg']:.3f} deg ({u['method']})"
)

# %% [markdown]
# On synthetic data we can check the check: does the stated bound cover the true error? The
# curvature describes how *precise* a minimum is, not whether it is the *right* one; on
# nbcalib's synthetic scenes the bias of the NID minimum (cast shadows in the camera image pull
# points towards their shadows) is often larger than the bound. docs/BENCHMARKS.md reports how
# often the bound covers the error over 30+ synthetic pairs.

# %%
err = pose_errors(result.T_camera_lidar, seq.T_camera_lidar)
covered = (
    100 * err["translation_error_m"] <= u["translation_total_cm"]
    and err["rotation_error_deg"] <= u["rotation_total_deg"]
)
print(
    f"true error {100 * err['translation_error_m']:.2f} cm / {err['rotation_error_deg']:.3f} deg: "
    f"{'inside' if covered else 'OUTSIDE'} the stated bound"
)

# %% [markdown]
# ### The cost around the result
#
# Each panel moves the result along one axis. A well-constrained result sits at the bottom of
# six clear valleys.

# %%
fig, axes = plt.subplots(1, 6, figsize=(18, 3), sharey=True)
for k, ax in enumerate(axes):
    x = q.curve_offsets[k] * (100.0 if k < 3 else np.degrees(1.0))
    ax.plot(x, q.curve_values[k])
    ax.axvline(0, color="k", lw=0.5)
    ax.set_xlabel(f"{AXIS_NAMES[k]} [{'cm' if k < 3 else 'deg'}]")
axes[0].set_ylabel("NID")
fig.tight_layout()

# %% [markdown]
# ## A result that should not be trusted
#
# Now the same cloud with the image of a *different* scene: nothing in the image matches the
# LiDAR, the cost is flat, and the check should say so.

# %%
other = generate_sequence(
    RigConfig(
        lidar="livox", camera="pinhole", scene="street", seed=7, duration=0.2, image_size=(640, 480)
    )
)
bad = nbcalib.calibrate(points, intensities, other.image, seq.camera, T_init=T_start, max_outer=2)
print("verdict:", bad.quality.verdict)
for reason in bad.quality.reasons:
    print(" -", reason)

# %% [markdown]
# ## The report on disk
#
# From the command line, `nbcalib report WORKDIR` (and the last step of `nbcalib run`) writes
# `WORKDIR/report/index.html`: LiDAR points over the image before and after refinement,
# coloured by depth and by intensity, an edge overlay, these curves, per-pair NID and the
# verdict. `nbcalib report WORKDIR --strict` exits with status 3 when the verdict is
# `suspect`, for scripts.
#
# ```bash
# nbcalib run recording.bag work/       # every stage, then the report
# nbcalib report work/ --strict
# nbcalib export work/ --format all     # tf2, URDF and OpenCV YAML of the result
# ```

# %% [markdown]
# ## What we checked
#
# The test suite runs this notebook (`tests/test_notebooks.py`) and checks what it showed:
#
# - the result is within 4 cm and 0.6 degrees of the truth, its verdict is `ok` with six valleys
#   centred on it, its uncertainty is within the verdict's limits and of the order of the true
#   error, and the inside/outside sentence is what the numbers say;
# - with the wrong image the verdict is `suspect`, for a flat cost: the curves rise less than a
#   third as much.
