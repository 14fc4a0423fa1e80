"""Synthetic LiDAR-camera rig with ground truth, for every LiDAR kind and camera model.

Pieces, each usable alone:

- :mod:`~nbcalib.synthetic.scene`: scenes of analytic primitives (:class:`Scene`), ray cast by
  :mod:`nbcalib.kernels.raycast` over a hierarchy from :mod:`~nbcalib.synthetic.bvh`;
  :func:`~nbcalib.synthetic.scenes.make_scene` generates the procedural rooms and streets of
  :mod:`~nbcalib.synthetic.scenes` with :mod:`~nbcalib.synthetic.builder`;
- :mod:`~nbcalib.synthetic.texture`: materials whose camera albedo and LiDAR reflectivity are
  correlated but not equal (the cross-modal gap);
- :mod:`~nbcalib.synthetic.lidar`: spinning and rosette LiDARs with noise and motion distortion;
- :mod:`~nbcalib.synthetic.motion`: ground-truth trajectories (nodding, driving, static);
- :mod:`~nbcalib.synthetic.render`: camera images through any camera model;
- :mod:`~nbcalib.synthetic.rig`: all of it together, one pair at a time;
- :mod:`~nbcalib.synthetic.writer`: files and bags as users have them (``nbcalib synth``);
- :mod:`~nbcalib.synthetic.effects`: switches that turn single camera/LiDAR differences off
  (``RigConfig.without``, ``nbcalib synth --without``).

The numba kernels are in :mod:`nbcalib.kernels` (``raycast``, ``synthetic_texture``,
``synthetic_shading``, ``synthetic_lidar``), their slow references in :mod:`nbcalib.reference`;
the modules here hold the configurations and the validating wrappers. Importing this package is
cheap: numba and the modules load on first use of a name.

Example
-------
>>> from nbcalib.synthetic import RigConfig, generate_sequence
>>> seq = generate_sequence(RigConfig(lidar="spinning64", camera="fisheye", scene="street"))
>>> seq.T_camera_lidar          # the answer a calibration should find
"""

from nbcalib._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    "nbcalib.synthetic",
    {
        "builder": ("SceneBuilder",),
        "effects": ("EFFECTS",),
        "lidar": (
            "LIDAR_PRESETS",
            "LidarConfig",
            "LidarScan",
            "RosetteLidarConfig",
            "SpinningLidarConfig",
            "lidar_preset",
            "simulate_scan",
        ),
        "motion": ("MotionConfig", "Trajectory", "make_trajectory"),
        "render": ("RenderConfig", "RenderedImage", "render_image"),
        "rig": (
            "DEFAULT_DURATION",
            "RigConfig",
            "SyntheticSequence",
            "camera_lidar_overlap",
            "default_T_camera_lidar",
            "generate_sequence",
        ),
        "scene": ("Scene", "SceneConfig"),
        "scenes": ("make_scene",),
        "texture": ("Material",),
    },
)
