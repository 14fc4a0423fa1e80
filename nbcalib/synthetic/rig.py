"""The synthetic LiDAR-camera rig: scene + trajectory + LiDAR scans + camera image + ground truth.

:func:`generate_sequence` produces one *pair* of the method (paper section III): a sequence of
LiDAR scans recorded while the rig moves (or holds still), and the camera image taken at the start
of the first scan, when the rig is at rest. Everything is expressed as the reference toolbox
expects it: the world frame is the LiDAR frame at the start of the first scan, the image has the
same time stamp as the first scan, and each scan's points are in the LiDAR frame of their own
firing time (distorted by the motion, as a real sweep).

The rig is the same for every pair of a configuration (one ``T_camera_lidar`` per ``seed``); each
pair gets a scene, trajectory and noise of its own, derived from ``(seed, pair)``.

``RigConfig.without`` switches single camera/LiDAR differences off
(:mod:`nbcalib.synthetic.effects`): the texture ones through the scene, the camera and LiDAR ones
through their configurations, ``motion`` through :meth:`SyntheticSequence.output_scans`, what
:mod:`nbcalib.synthetic.writer` writes. Every random draw stays where it was, so a pair with a
switch differs from the same pair without it by that switch only.

Example
-------
>>> from nbcalib.synthetic import RigConfig, generate_sequence
>>> seq = generate_sequence(RigConfig(lidar="livox", camera="omnidir", scene="street", seed=1))
>>> seq.image.shape, len(seq.scans), seq.T_camera_lidar.shape
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from nbcalib.camera import CAMERA_MODELS, CameraModel, example_camera
from nbcalib.synthetic.effects import (
    TEXTURE_EFFECTS,
    check_effects,
    lidar_without,
    render_without,
)
from nbcalib.synthetic.lidar import (
    LIDAR_PRESETS,
    LidarConfig,
    LidarScan,
    lidar_preset,
    simulate_scan,
)
from nbcalib.synthetic.motion import MotionConfig, Trajectory, make_trajectory
from nbcalib.synthetic.render import RenderConfig, RenderedImage, render_image
from nbcalib.synthetic.scene import SCENE_KINDS, Scene, SceneConfig
from nbcalib.synthetic.scenes import make_scene
from nbcalib.transforms import invert_T, make_T, so3_exp, transform_points

__all__ = [
    "DEFAULT_DURATION",
    "RING_IMAGE_SIZE",
    "RigConfig",
    "RingCamera",
    "SyntheticSequence",
    "camera_lidar_overlap",
    "default_T_camera_lidar",
    "generate_ring",
    "generate_sequence",
    "ring_cameras",
]

#: Default seconds of LiDAR data per pair: a few seconds of nodding for spinning LiDARs (more for
#: sparse ones), ten seconds of rosette for the Livox (the reference's procedure asks 10-15 s).
DEFAULT_DURATION = {
    "spinning16": 3.0,
    "spinning32": 2.0,
    "spinning64": 2.0,
    "spinning128": 1.5,
    "livox": 10.0,
}

#: Rotation from the LiDAR body axes to a camera optical frame looking along LiDAR x, no roll:
#: camera x (right) = -y_lidar, camera y (down) = -z_lidar, camera z (forward) = x_lidar.
R_OPTICAL_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class RigConfig:
    """What to simulate; every field has a realistic default.

    Parameters
    ----------
    lidar : str
        A key of :data:`nbcalib.synthetic.lidar.LIDAR_PRESETS`.
    camera : str
        A camera model of :data:`nbcalib.camera.CAMERA_MODELS` (the example lens of the kind).
    scene : str
        ``"room"`` or ``"street"``.
    seed : int
        Seed of everything; the same seed gives identical output.
    duration : float or None
        Seconds of LiDAR data per pair (rounded to whole scans); None: :data:`DEFAULT_DURATION`.
    motion : str or None
        ``"nod"``, ``"drive"`` or ``"static"``; None: nodding for spinning LiDARs, static for the
        rosette.
    image_size : tuple of 2 ints or None
        ``(width, height)`` of the camera image; None: 1280 x 960 (equirectangular 1280 x 640).
    color : bool
        RGB images (else grey).
    modality_gap : float
        Camera/LiDAR texture gap in [0, 1] (:mod:`nbcalib.synthetic.texture`).
    without : tuple of str
        Camera/LiDAR differences switched off, each on its own: names of
        :data:`nbcalib.synthetic.effects.EFFECTS` (a comma-separated string is accepted; kept in
        that order, each once; unknown names raise ValueError). Empty (default): the full rig,
        bit for bit. They apply on top of ``lidar_config`` and ``render_config`` too. The
        texture switches compose with ``modality_gap`` as the effects module says: at gap 0
        ``materials``, ``elements`` and ``lidar-texture`` change nothing, ``camera-texture``
        acts on both sensors.
    T_camera_lidar : array_like of shape (4, 4) or None
        Ground-truth extrinsics; None: :func:`default_T_camera_lidar` of the seed.
    parallel : bool
        Use the parallel kernels (same output).
    lidar_config, motion_config, render_config : optional
        Full configurations replacing the presets (their own seeds are replaced per pair).
    camera_model : CameraModel or None
        A camera replacing the example of ``camera``.
    cameras : tuple of str
        A camera ring (:func:`ring_cameras`, :func:`generate_ring`): one model per camera,
        ``model`` or ``model:WxH``, the first the rig's reference camera. Empty (default): the
        one camera ``camera``.
    """

    lidar: str = "spinning64"
    camera: str = "pinhole"
    scene: str = "room"
    seed: int = 0
    duration: float | None = None
    motion: str | None = None
    image_size: tuple[int, int] | None = None
    color: bool = False
    modality_gap: float = 1.0
    without: tuple[str, ...] = ()
    T_camera_lidar: tuple | None = None
    parallel: bool = False
    lidar_config: LidarConfig | None = None
    motion_config: MotionConfig | None = None
    render_config: RenderConfig | None = None
    camera_model: CameraModel | None = field(default=None, repr=False)
    cameras: tuple[str, ...] = ()

    def __post_init__(self):
        if self.lidar_config is None and self.lidar not in LIDAR_PRESETS:
            raise ValueError(f"unknown LiDAR {self.lidar!r}; expected one of {list(LIDAR_PRESETS)}")
        if self.camera_model is None and self.camera not in CAMERA_MODELS:
            raise ValueError(f"unknown camera {self.camera!r}; expected one of {CAMERA_MODELS}")
        if self.scene not in SCENE_KINDS:
            raise ValueError(f"unknown scene {self.scene!r}; expected one of {SCENE_KINDS}")
        if self.duration is not None and not self.duration > 0:
            raise ValueError(f"duration must be > 0 s, got {self.duration}")
        object.__setattr__(self, "without", check_effects(self.without))
        if isinstance(self.cameras, str):
            object.__setattr__(self, "cameras", tuple(self.cameras.split(",")))
        for text in self.cameras:
            model, _ = _ring_spec(text)
            if model not in CAMERA_MODELS:
                raise ValueError(f"unknown camera {model!r}; expected one of {CAMERA_MODELS}")
        if self.T_camera_lidar is not None:
            T = np.asarray(self.T_camera_lidar, dtype=np.float64)
            invert_T(T)  # validates a rigid 4 x 4
            object.__setattr__(self, "T_camera_lidar", tuple(map(tuple, T.tolist())))

    def lidar_model(self) -> LidarConfig:
        """The LiDAR configuration (preset or ``lidar_config``), LiDAR switches applied."""
        lidar = self.lidar_config if self.lidar_config is not None else lidar_preset(self.lidar)
        return lidar_without(lidar, self.without)

    def camera_object(self) -> CameraModel:
        """The camera (``camera_model`` or the example of ``camera`` at ``image_size``)."""
        if self.camera_model is not None:
            return self.camera_model
        width, height = self.image_size or (1280, 960)
        return example_camera(self.camera, width, height)


def default_T_camera_lidar(lidar_kind: str, seed: int) -> np.ndarray:
    """A ground-truth ``T_camera_lidar`` like a real rig's, drawn from ``seed``.

    The camera sits 5 to 30 cm from the LiDAR in a random direction. A camera next to a spinning
    LiDAR looks anywhere around it (sideways or backwards as well as forwards: yaw uniform in
    +-180 degrees, pitch +-10, roll +-5); next to a rosette LiDAR it looks into the LiDAR's field of
    view (yaw and pitch +-8 degrees, roll +-5), so the two always overlap.

    Parameters
    ----------
    lidar_kind : str
        ``"spinning"`` or ``"rosette"``.
    seed : int
        Seed of the draw.

    Returns
    -------
    ndarray of shape (4, 4), float64
        ``T_camera_lidar``: ``p_camera = T_camera_lidar @ p_lidar``.
    """
    rng = np.random.default_rng([seed, 0xCA11B])
    spread = 180.0 if lidar_kind == "spinning" else 8.0
    yaw = math.radians(rng.uniform(-spread, spread))
    pitch = math.radians(
        rng.uniform(-10.0, 10.0) if lidar_kind == "spinning" else rng.uniform(-8, 8)
    )
    roll = math.radians(rng.uniform(-5.0, 5.0))
    # camera axes in the LiDAR frame: turn a forward-looking camera by yaw (about LiDAR z), then
    # pitch (about the camera's x axis, positive looks down), then roll (about its optical axis)
    R_lidar_forward = R_OPTICAL_BODY.T
    R_lidar_camera = (
        so3_exp(np.array([0.0, 0.0, yaw]))
        @ R_lidar_forward
        @ so3_exp(np.array([-pitch, 0.0, 0.0]))
        @ so3_exp(np.array([0.0, 0.0, roll]))
    )
    direction = rng.normal(size=3)
    t_lidar_camera = direction / np.linalg.norm(direction) * rng.uniform(0.05, 0.30)
    return invert_T(make_T(R_lidar_camera, t_lidar_camera))


@dataclass(frozen=True, eq=False)
class SyntheticSequence:
    """One synthetic pair: LiDAR scans while moving, the camera image, and the ground truth.

    Attributes
    ----------
    scans : tuple of LidarScan
        The scans in time order; scan ``k`` starts at ``k * lidar.scan_period`` seconds.
    image : ndarray of shape (H, W) or (H, W, 3), uint8
        Camera image taken at time 0 (the first scan's start), grey or RGB.
    camera : CameraModel
        The camera.
    T_camera_lidar : ndarray of shape (4, 4), float64
        Ground truth, ``p_camera = T_camera_lidar @ p_lidar``.
    trajectory : Trajectory
        Ground-truth ``T_world_lidar(t)``; the world is the LiDAR frame at time 0.
    scene : Scene
        The scene (world frame).
    lidar : LidarConfig
        The LiDAR model used.
    motion : MotionConfig
        The motion used.
    rendered : RenderedImage
        Per-pixel ground truth of the image (range, primitive, bearing).
    config : RigConfig
        The configuration that produced the sequence.
    pair : int
        Index of the pair.
    """

    scans: tuple[LidarScan, ...]
    image: np.ndarray
    camera: CameraModel
    T_camera_lidar: np.ndarray
    trajectory: Trajectory
    scene: Scene
    lidar: LidarConfig
    motion: MotionConfig
    rendered: RenderedImage = field(repr=False)
    config: RigConfig = field(repr=False)
    pair: int = 0

    @property
    def T_lidar_camera(self) -> np.ndarray:
        """Inverse of :attr:`T_camera_lidar` (the ``calib.json`` direction)."""
        return invert_T(self.T_camera_lidar)

    @property
    def image_stamp(self) -> float:
        """Time of the image, seconds (0: the start of the first scan)."""
        return 0.0

    @property
    def scan_stamps(self) -> np.ndarray:
        """Start time of each scan, seconds, shape (S,)."""
        return np.array([scan.stamp for scan in self.scans])

    @property
    def scan_poses_begin(self) -> np.ndarray:
        """``T_world_lidar`` at each scan's start, shape (S, 4, 4)."""
        return self.trajectory.poses(self.scan_stamps)

    @property
    def scan_poses_end(self) -> np.ndarray:
        """``T_world_lidar`` at each scan's end (start + scan period), shape (S, 4, 4)."""
        return self.trajectory.poses(self.scan_stamps + self.lidar.scan_period)

    def T_world_lidar(self, t) -> np.ndarray:
        """Ground-truth pose(s) at time(s) ``t``, seconds: (4, 4) or (N, 4, 4)."""
        return self.trajectory.poses(t)

    def dense_cloud(self) -> tuple[np.ndarray, np.ndarray]:
        """All points deskewed with the true trajectory, in the LiDAR frame at time 0.

        Returns
        -------
        points_lidar : ndarray of shape (N, 3), float64
            Metres, the frame the reference toolbox's dense cloud uses.
        intensities : ndarray of shape (N,), float64
            In [0, 255].
        """
        points = [
            transform_points(T, scan.points_undistorted)
            for T, scan in zip(self.scan_poses_begin, self.scans)
        ]
        return np.concatenate(points), np.concatenate([s.intensities for s in self.scans])

    def output_scans(self) -> tuple[LidarScan, ...]:
        """The scans as :mod:`nbcalib.synthetic.writer` writes them.

        :attr:`scans`; or, with ``"motion"`` in ``config.without``, a single scan holding every
        point deskewed with the true trajectory into the LiDAR frame at time 0 (the world frame,
        :meth:`dense_cloud`): time 0, stamp 0, each point's ring and primitive as simulated. It
        is a static, perfectly deskewed cloud with the density of the moving sweep, which a
        static integration only accumulates.

        Returns
        -------
        tuple of LidarScan
        """
        if "motion" not in self.config.without:
            return self.scans
        points, intensities = self.dense_cloud()
        scan = LidarScan(
            points=points,
            intensities=intensities,
            times=np.zeros(len(points)),
            rings=np.concatenate([s.rings for s in self.scans]),
            stamp=0.0,
            points_undistorted=points,
            prim=np.concatenate([s.prim for s in self.scans]),
        )
        return (scan,)


def _pair_seeds(seed: int, pair: int) -> dict[str, int]:
    """Independent seeds of the parts of one pair, from ``(seed, pair)``."""
    children = np.random.SeedSequence([seed, pair]).spawn(4)
    names = ("scene", "motion", "lidar", "render")
    return {n: int(c.generate_state(1)[0]) for n, c in zip(names, children)}


def generate_sequence(
    config: RigConfig | None = None,
    *,
    pair: int = 0,
    progress: Callable[[int, int, str], None] | None = None,
) -> SyntheticSequence:
    """Simulate one pair: scene, trajectory, every scan and the camera image.

    Parameters
    ----------
    config : RigConfig, optional
        What to simulate (defaults: a 64-beam LiDAR nodding in a room, a pinhole camera).
    pair : int
        Index of the pair: pairs of one configuration share the rig, not the scene.
    progress : callable, optional
        Called as ``progress(done, total, what)`` after each step.

    Returns
    -------
    SyntheticSequence
    """
    config = config or RigConfig()
    seeds = _pair_seeds(config.seed, pair)
    lidar = config.lidar_model()
    scene = make_scene(
        SceneConfig(
            kind=config.scene,
            seed=seeds["scene"],
            modality_gap=config.modality_gap,
            without=tuple(e for e in config.without if e in TEXTURE_EFFECTS),
        )
    )
    kind = config.motion or ("static" if lidar.kind == "rosette" else "nod")
    motion = replace(config.motion_config or MotionConfig(kind=kind), seed=seeds["motion"])
    duration = config.duration or DEFAULT_DURATION.get(lidar.name, 2.0)
    n_scans = max(1, round(duration / lidar.scan_period))
    trajectory = make_trajectory(motion, n_scans * lidar.scan_period)
    camera = config.camera_object()
    if config.T_camera_lidar is not None:
        T_camera_lidar = np.array(config.T_camera_lidar, dtype=np.float64)
    else:
        T_camera_lidar = default_T_camera_lidar(lidar.kind, config.seed)
    total = n_scans + 1

    render = config.render_config or RenderConfig(color=config.color)
    render = replace(render, seed=seeds["render"], parallel=config.parallel or render.parallel)
    render = render_without(render, config.without)
    T_world_camera = trajectory.pose(0.0) @ invert_T(T_camera_lidar)
    rendered = render_image(scene, camera, T_world_camera, render)
    if progress:
        progress(1, total, "image")

    rng = np.random.default_rng(seeds["lidar"])
    scans = []
    for k in range(n_scans):
        scan = simulate_scan(
            scene, lidar, trajectory, k * lidar.scan_period, rng, parallel=config.parallel
        )
        scans.append(scan)
        if progress:
            progress(k + 2, total, "scans")
    return SyntheticSequence(
        scans=tuple(scans),
        image=rendered.image,
        camera=camera,
        T_camera_lidar=T_camera_lidar,
        trajectory=trajectory,
        scene=scene,
        lidar=lidar,
        motion=motion,
        rendered=rendered,
        config=config,
        pair=pair,
    )


def camera_lidar_overlap(sequence: SyntheticSequence, *, cell_px: int = 16) -> dict[str, float]:
    """How much the camera and the LiDAR see of each other in a sequence.

    Parameters
    ----------
    sequence : SyntheticSequence
        The pair to check.
    cell_px : int
        Size of the image cells counted as covered, pixels.

    Returns
    -------
    dict
        ``points_in_image``: fraction of the dense cloud's points that project into the image;
        ``image_coverage``: fraction of the image's valid cells (pixels with a ray) hit by at
        least one projected point.
    """
    points, _ = sequence.dense_cloud()
    camera = sequence.camera
    uv, valid = camera.project(transform_points(sequence.T_camera_lidar, points), in_image=True)
    pixels = np.floor(uv[valid] + 0.5).astype(np.int64)
    cells_w = -(-camera.width // cell_px)
    cells_h = -(-camera.height // cell_px)
    covered = np.zeros((cells_h, cells_w), dtype=bool)
    covered[pixels[:, 1] // cell_px, pixels[:, 0] // cell_px] = True
    rays = np.isfinite(sequence.rendered.bearings[..., 0])
    has_ray = np.zeros((cells_h, cells_w), dtype=bool)
    vv, uu = np.nonzero(rays)
    has_ray[vv // cell_px, uu // cell_px] = True
    return {
        "points_in_image": float(valid.mean()) if valid.size else 0.0,
        "image_coverage": float((covered & has_ray).sum() / max(1, has_ray.sum())),
    }


# ============================================================================ camera rings
#: Image size of a ring's cameras after the first (the first has the rig's ``image_size``).
RING_IMAGE_SIZE = (1024, 768)


@dataclass(frozen=True)
class RingCamera:
    """One camera of a synthetic camera ring (:func:`ring_cameras`).

    Attributes
    ----------
    name : str
        ``cam0``, ``cam1``, ...: the bag's topics are ``/<name>/image`` and
        ``/<name>/camera_info``, its optical frame ``<name>``.
    camera : CameraModel
    T_camera_lidar : ndarray of shape (4, 4)
        Ground truth, ``p_camera = T_camera_lidar @ p_lidar``.
    """

    name: str
    camera: CameraModel
    T_camera_lidar: np.ndarray = field(repr=False)


def _ring_spec(text: str) -> tuple[str, tuple[int, int] | None]:
    """``model`` or ``model:WxH`` -> (model, size or None)."""
    model, _, size = text.strip().partition(":")
    if not size:
        return model, None
    try:
        width, height = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise ValueError(f"camera {text!r}: expected MODEL or MODEL:WxH") from None
    if width < 16 or height < 16:
        raise ValueError(f"camera {text!r}: the image must be at least 16 x 16")
    return model, (width, height)


def ring_cameras(config: RigConfig) -> list[RingCamera]:
    """The cameras of ``config.cameras`` around the LiDAR, each with its own pose and lens.

    The first camera is the rig's own (``config.camera_object()`` at ``config.T_camera_lidar``
    or the seed's :func:`default_T_camera_lidar`; its model is the ring's first entry), so a
    ring's first camera sees exactly what a one-camera rig of the same seed sees. Camera ``k``
    is the first one turned about the LiDAR's z axis by ``k / n`` of a full turn around a
    spinning LiDAR (the side and rear cameras of a car), or spread over +-20 degrees in front
    of a rosette LiDAR (whose field of view is about 70 degrees), then moved by up to 5 cm and
    turned by up to 2 degrees at random: every camera has an extrinsic of its own. An entry
    ``model:WxH`` sets its image size; by default the first has ``config.image_size`` (1280 x
    960) and the others :data:`RING_IMAGE_SIZE`.
    """
    specs = [_ring_spec(text) for text in config.cameras] or [(config.camera, None)]
    lidar = config.lidar_model()
    if config.T_camera_lidar is not None:
        T0 = np.array(config.T_camera_lidar, dtype=np.float64)
    else:
        T0 = default_T_camera_lidar(lidar.kind, config.seed)
    T_lidar_cam0 = invert_T(T0)
    n = len(specs)
    out = []
    for k, (model, size) in enumerate(specs):
        if k == 0:
            camera = config.camera_object() if size is None and model == config.camera else None
            if camera is None:
                width, height = size or config.image_size or (1280, 960)
                camera = example_camera(model, width, height)
            out.append(RingCamera("cam0", camera, T0))
            continue
        width, height = size or RING_IMAGE_SIZE
        camera = example_camera(model, width, height)
        rng = np.random.default_rng([config.seed, 0x5109, k])
        if lidar.kind == "rosette":
            yaw = math.radians(-20.0 + 40.0 * k / max(n - 1, 1))
        else:
            yaw = 2.0 * math.pi * k / n
        R_turn = so3_exp(np.array([0.0, 0.0, yaw]))
        jitter = so3_exp(np.radians(rng.uniform(-2.0, 2.0, size=3)))
        R = R_turn @ T_lidar_cam0[:3, :3] @ jitter
        t = R_turn @ T_lidar_cam0[:3, 3] + rng.uniform(-0.05, 0.05, size=3)
        out.append(RingCamera(f"cam{k}", camera, invert_T(make_T(R, t))))
    return out


def generate_ring(
    config: RigConfig,
    *,
    pair: int = 0,
    progress: Callable[[int, int, str], None] | None = None,
) -> list[SyntheticSequence]:
    """One pair seen by every camera of ``config.cameras`` (:func:`ring_cameras`).

    One scene, trajectory and set of scans; an image per camera, each taken at time 0. The
    first sequence is :func:`generate_sequence` of the first camera; the others share its
    scans (the same objects) and differ in camera, image and ground truth.
    """
    cameras = ring_cameras(config)
    first = cameras[0]
    single = replace(
        config, cameras=(), camera_model=first.camera, T_camera_lidar=first.T_camera_lidar
    )
    base = generate_sequence(single, pair=pair, progress=progress)
    sequences = [base]
    seeds = _pair_seeds(config.seed, pair)
    for k, ring in enumerate(cameras[1:], start=1):
        render = config.render_config or RenderConfig(color=config.color)
        seed = int(np.random.SeedSequence([seeds["render"], k]).generate_state(1)[0])
        render = replace(render, seed=seed, parallel=config.parallel or render.parallel)
        render = render_without(render, config.without)
        T_world_camera = base.trajectory.pose(0.0) @ invert_T(ring.T_camera_lidar)
        rendered = render_image(base.scene, ring.camera, T_world_camera, render)
        sequences.append(
            replace(
                base,
                image=rendered.image,
                camera=ring.camera,
                T_camera_lidar=ring.T_camera_lidar,
                rendered=rendered,
            )
        )
    return sequences
