"""Synthetic LiDAR-camera rig with ground truth, for every LiDAR kind and camera model.

Pieces, each usable alone:

- :mod:`~nbcalib.synthetic.scene`: scenes of analytic primitives (:class:`Scene`), ray cast by
  :mod:`nbcalib.kernels.raycast` over a hierarchy from :mod:`~nbcalib.synthetic.bvh`;
  :func:`make_scene` generates the procedural rooms and streets of
  :mod:`~nbcalib.synthetic.scenes` with :mod:`~nbcalib.synthetic.builder`;
- :mod:`~nbcalib.synthetic.texture`: materials whose camera albedo and LiDAR reflectivity are
  correlated but not equal (the cross-modal gap);
- :mod:`~nbcalib.synthetic.lidar`: spinning and rosette LiDARs with noise and motion distortion;
- :mod:`~nbcalib.synthetic.motion`: ground-truth trajectories (nodding, driving, static);
- :mod:`~nbcalib.synthetic.render`: camera images through any camera model;
- :mod:`~nbcalib.synthetic.rig`: all of it together, one pair at a time;
- :mod:`~nbcalib.synthetic.writer`: files and bags as users have them (``nbcalib synth``).

The numba kernels are in :mod:`nbcalib.kernels` (``raycast``, ``synthetic_texture``,
``synthetic_shading``, ``synthetic_lidar``), their slow references in :mod:`nbcalib.reference`;
the modules here hold the configurations and the validating wrappers.

Example
-------
>>> from nbcalib.synthetic import RigConfig, generate_sequence
>>> seq = generate_sequence(RigConfig(lidar="spinning64", camera="fisheye", scene="street"))
>>> seq.T_camera_lidar          # the answer a calibration should find
"""

from nbcalib.synthetic.builder import SceneBuilder
from nbcalib.synthetic.lidar import (
    LIDAR_PRESETS,
    LidarConfig,
    LidarScan,
    RosetteLidarConfig,
    SpinningLidarConfig,
    lidar_preset,
    simulate_scan,
)
from nbcalib.synthetic.motion import MotionConfig, Trajectory, make_trajectory
from nbcalib.synthetic.render import RenderConfig, RenderedImage, render_image
from nbcalib.synthetic.rig import (
    DEFAULT_DURATION,
    RigConfig,
    SyntheticSequence,
    camera_lidar_overlap,
    default_T_camera_lidar,
    generate_sequence,
)
from nbcalib.synthetic.scene import Scene, SceneConfig, make_scene
from nbcalib.synthetic.texture import Material

__all__ = [
    "DEFAULT_DURATION",
    "LIDAR_PRESETS",
    "LidarConfig",
    "LidarScan",
    "Material",
    "MotionConfig",
    "RenderConfig",
    "RenderedImage",
    "RigConfig",
    "RosetteLidarConfig",
    "Scene",
    "SceneBuilder",
    "SceneConfig",
    "SpinningLidarConfig",
    "SyntheticSequence",
    "Trajectory",
    "camera_lidar_overlap",
    "default_T_camera_lidar",
    "generate_sequence",
    "lidar_preset",
    "make_scene",
    "make_trajectory",
    "render_image",
    "simulate_scan",
]
