"""Camera images of a scene through any camera model: one ray per pixel, shading, sensor noise.

:func:`render_image` unprojects every pixel centre with ``camera.unproject`` (so every model of
:mod:`nbcalib.camera` renders alike, and pixels outside a model's domain stay black), casts the
rays from the camera centre into the scene, and shades each hit:

``radiance = albedo * (ambient * (0.7 + 0.3 n_z) + sun * max(0, n . s) * lit + sum_lights ...)``

with shadows from shadow rays towards the sun and the point lights (camera only: the LiDAR sees
reflectivity, not light). Rays that hit nothing see the sky. The linear image is exposed
automatically (its 95th percentile maps to 0.85), blurred a little as real optics do, converted
to sRGB-like gamma, given shot and read noise, and quantised to 8 bits: grey (luminance) or RGB.

``RenderConfig(shading=False)`` replaces the irradiance by the constant ``ambient +
sun_irradiance`` (radiance = albedo x a constant: no normals, sun angle, point lights or
shadows); ``shadows=False`` keeps the shading without cast shadows; zero blur and noise give the
image without optics (``nbcalib synth --without shading,shadows,optics``,
:mod:`nbcalib.synthetic.effects`). The texture switches come with the scene (``Scene.without``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.kernels import synthetic_shading as _sh
from nbcalib.kernels.synthetic_texture import LUMA
from nbcalib.synthetic.scene import Scene
from nbcalib.synthetic.texture import texture_bits

__all__ = ["RenderConfig", "RenderedImage", "radiance", "render_image"]


@dataclass(frozen=True)
class RenderConfig:
    """How a camera image is rendered.

    Parameters
    ----------
    color : bool
        RGB image (H, W, 3) if True, grey (H, W) if False.
    exposure : float or None
        Linear gain applied before the gamma; None: automatic (95th percentile -> 0.85).
    gamma : float
        Display gamma of the 8-bit output.
    blur_sigma_px : float
        Gaussian blur of the optics, pixels (0: none).
    read_noise : float
        Standard deviation of the additive sensor noise, as a fraction of full scale.
    shot_noise : float
        Photon noise: standard deviation ``sqrt(shot_noise * value)``, fraction of full scale.
    shadows : bool
        Cast shadow rays.
    shading : bool
        Shade with the surface normal and the lights; False: every surface gets the irradiance
        ``ambient + sun_irradiance`` (no shadows either), so the radiance is the albedo times a
        constant (auto exposure maps it as any image).
    seed : int
        Seed of the sensor noise.
    parallel : bool
        Use the parallel kernels (same image).
    """

    color: bool = False
    exposure: float | None = None
    gamma: float = 2.2
    blur_sigma_px: float = 0.6
    read_noise: float = 0.006
    shot_noise: float = 0.0008
    shadows: bool = True
    shading: bool = True
    seed: int = 0
    parallel: bool = False


@dataclass(frozen=True, eq=False)
class RenderedImage:
    """A rendered image and what each pixel saw.

    Attributes
    ----------
    image : ndarray of shape (H, W) or (H, W, 3), uint8
        The camera image (grey or RGB).
    range : ndarray of shape (H, W), float64
        Distance from the camera centre to the surface seen at each pixel centre along its ray,
        metres; ``inf`` for the sky, NaN outside the camera model's domain.
    prim : ndarray of shape (H, W), int64
        Scene primitive seen at each pixel, -1 for none.
    bearings : ndarray of shape (H, W, 3), float64
        Unit ray of each pixel centre in the camera frame (NaN outside the domain).
    """

    image: np.ndarray
    range: np.ndarray
    prim: np.ndarray
    bearings: np.ndarray


def _pixel_angle(bearings) -> np.ndarray:
    """Angle between neighbouring pixels' rays, radians, shape (H * W,) (the larger of u and v)."""
    du = np.linalg.norm(np.diff(bearings, axis=1, append=bearings[:, -2:-1]), axis=2)
    dv = np.linalg.norm(np.diff(bearings, axis=0, append=bearings[-2:-1]), axis=2)
    angle = np.fmax(du, dv).ravel()
    fallback = np.nanmedian(angle) if np.isfinite(angle).any() else 0.0
    return np.where(np.isfinite(angle), angle, fallback)


def radiance(
    scene: Scene, origin, directions, pixel_angle, *, shadows=True, shading=True, parallel=False
):
    """Linear RGB radiance along camera rays (wraps the shading kernel; no exposure, blur, noise).

    The modality gap and the texture switches are the scene's (``scene.without``).

    Parameters
    ----------
    scene : Scene
        The scene and its lighting.
    origin : ndarray of shape (3,), float64
        Camera centre, world frame, metres.
    directions : ndarray of shape (N, 3), float64
        Unit ray directions, world frame; NaN rows stay black.
    pixel_angle : ndarray of shape (N,), float64
        Angular size of each ray's pixel, radians (texture antialiasing).
    shadows : bool
        Cast shadow rays.
    shading : bool
        False: the irradiance is ``ambient + sun_irradiance`` everywhere (:class:`RenderConfig`).
    parallel : bool
        Use the parallel kernel (same result).

    Returns
    -------
    radiance : ndarray of shape (N, 3), float64
    t : ndarray of shape (N,), float64
        Distance to the surface seen, metres; ``inf`` for the sky, NaN for invalid rays.
    prim : ndarray of shape (N,), int64
        Primitive seen, -1 for none.
    """
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    n = directions.shape[0]
    if directions.shape != (n, 3):
        raise ValueError(f"directions must have shape (N, 3), got {directions.shape}")
    light = scene.lighting
    sun = np.zeros(4)
    sun[:3] = np.asarray(light.sun_direction) / np.linalg.norm(light.sun_direction)
    sun[3] = light.sun_irradiance
    lights = np.asarray(light.point_lights, dtype=np.float64).reshape(-1, 4)
    out_radiance = np.empty((n, 3))
    out_t = np.empty(n)
    out_prim = np.empty(n, dtype=np.int64)
    kernel = _sh._shade_parallel if parallel else _sh._shade
    kernel(
        scene.prims,
        scene.bvh_bounds,
        scene.bvh_nodes,
        scene.bvh_order,
        scene.materials,
        float(scene.modality_gap),
        texture_bits(scene.without),
        np.ascontiguousarray(origin, dtype=np.float64),
        directions,
        np.ascontiguousarray(np.broadcast_to(pixel_angle, (n,)), dtype=np.float64),
        sun,
        float(light.ambient),
        np.ascontiguousarray(lights),
        np.asarray(light.sky_top, dtype=np.float64),
        np.asarray(light.sky_horizon, dtype=np.float64),
        bool(shadows),
        bool(shading),
        out_radiance,
        out_t,
        out_prim,
    )
    return out_radiance, out_t, out_prim


def render_image(
    scene: Scene,
    camera: CameraModel,
    T_world_camera,
    config: RenderConfig | None = None,
) -> RenderedImage:
    """Render what ``camera`` sees from pose ``T_world_camera``.

    Parameters
    ----------
    scene : Scene
        The scene (world frame).
    camera : CameraModel
        Any camera model; one ray per pixel centre through ``camera.unproject``.
    T_world_camera : ndarray of shape (4, 4), float64
        Pose of the camera optical frame in the world.
    config : RenderConfig, optional
        Colour, exposure, blur, noise, shadows.

    Returns
    -------
    RenderedImage
    """
    config = config or RenderConfig()
    T_world_camera = np.asarray(T_world_camera, dtype=np.float64)
    if T_world_camera.shape != (4, 4) or not np.all(np.isfinite(T_world_camera)):
        raise ValueError("T_world_camera must be a finite 4 x 4 matrix")
    h, w = camera.height, camera.width
    bearings = camera.unproject(camera.pixel_grid())
    directions = bearings @ T_world_camera[:3, :3].T
    origin = T_world_camera[:3, 3]
    light, distance, prim = radiance(
        scene,
        origin,
        directions,
        _pixel_angle(bearings.reshape(h, w, 3)),
        shadows=config.shadows,
        shading=config.shading,
        parallel=config.parallel,
    )
    light = light.reshape(h, w, 3)
    valid = np.isfinite(bearings[:, 0]).reshape(h, w)
    if config.exposure is None:
        luminance = light[valid] @ np.asarray(LUMA)
        key = np.percentile(luminance, 95.0) if luminance.size else 1.0
        exposure = 0.85 / key if key > 0 else 1.0
    else:
        exposure = config.exposure
    linear = light * exposure
    if not config.color:
        linear = (linear @ np.asarray(LUMA))[..., None]
    if config.blur_sigma_px > 0:
        import cv2

        linear = cv2.GaussianBlur(linear, (0, 0), config.blur_sigma_px).reshape(linear.shape)
    value = np.clip(linear, 0.0, 1.0) ** (1.0 / config.gamma)
    if config.read_noise > 0 or config.shot_noise > 0:
        rng = np.random.default_rng([config.seed, 0xCA3E7A])
        sigma = np.sqrt(config.read_noise**2 + config.shot_noise * value)
        value = value + sigma * rng.standard_normal(value.shape)
    value[~valid] = 0.0
    image = np.clip(np.rint(255.0 * value), 0, 255).astype(np.uint8)
    if not config.color:
        image = image[..., 0]

    return RenderedImage(
        image=np.ascontiguousarray(image),
        range=distance.reshape(h, w),
        prim=prim.reshape(h, w),
        bearings=bearings.reshape(h, w, 3),
    )
