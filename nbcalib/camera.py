"""Camera models: projection of camera-frame points to pixels, Jacobians, unprojection.

Seven models, with the parameter layouts of the reference toolbox's ``calib.json``
(docs/conventions.md section 7)::

    model                intrinsics           distortion_coeffs
    pinhole              fx fy cx cy          (none)
    plumb_bob            fx fy cx cy          k1 k2 p1 p2 k3
    rational_polynomial  fx fy cx cy          k1 k2 p1 p2 k3 k4 k5 k6
    fisheye (equidistant) fx fy cx cy         k1 k2 k3 k4          (Kannala-Brandt, as cv2.fisheye)
    atan                 fx fy cx cy          omega                (FOV model)
    omnidir              fx fy cx cy xi       k1 k2 p1 p2          (unified / Mei model)
    equirectangular      W H                  (none)

Example
-------
>>> from nbcalib.camera import create_camera
>>> cam = create_camera("plumb_bob", [500, 500, 319.5, 239.5], [-0.1, 0.01, 0, 0, 0], 640, 480)
>>> uv, valid = cam.project([[0.1, -0.2, 2.0]])
>>> bearings = cam.unproject(uv)      # unit vectors along the same rays

:class:`CameraModel` is the validating public wrapper of the kernels in
:mod:`nbcalib.kernels.projection`, :mod:`nbcalib.kernels.projection_batch` and
:mod:`nbcalib.kernels.unprojection`; kernels elsewhere use ``camera.model_id`` and
``camera.params`` with ``project_point`` / ``unproject_pixel`` directly.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from nbcalib.kernels import projection as _k
from nbcalib.kernels import projection_batch as _kb
from nbcalib.kernels import unprojection as _ku

__all__ = [
    "CAMERA_MODELS",
    "CameraModel",
    "camera_from_camera_info",
    "camera_from_opencv",
    "camera_to_camera_info",
    "create_camera",
    "example_camera",
    "offset_intrinsics",
]


@dataclass(frozen=True)
class _ModelSpec:
    model_id: int
    intrinsic_names: tuple[str, ...]
    distortion_names: tuple[str, ...]


_SPECS: dict[str, _ModelSpec] = {
    "pinhole": _ModelSpec(_k.PINHOLE, ("fx", "fy", "cx", "cy"), ()),
    "plumb_bob": _ModelSpec(_k.PLUMB_BOB, ("fx", "fy", "cx", "cy"), ("k1", "k2", "p1", "p2", "k3")),
    "rational_polynomial": _ModelSpec(
        _k.RATIONAL_POLYNOMIAL,
        ("fx", "fy", "cx", "cy"),
        ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    ),
    "fisheye": _ModelSpec(_k.FISHEYE, ("fx", "fy", "cx", "cy"), ("k1", "k2", "k3", "k4")),
    "atan": _ModelSpec(_k.ATAN, ("fx", "fy", "cx", "cy"), ("omega",)),
    "omnidir": _ModelSpec(_k.OMNIDIR, ("fx", "fy", "cx", "cy", "xi"), ("k1", "k2", "p1", "p2")),
    "equirectangular": _ModelSpec(_k.EQUIRECTANGULAR, ("W", "H"), ()),
}

#: Canonical model names, in the order of the docs.
CAMERA_MODELS: tuple[str, ...] = tuple(_SPECS)

#: Other names accepted on input (ROS calls Kannala-Brandt "equidistant").
MODEL_ALIASES: dict[str, str] = {"equidistant": "fisheye", "kannala_brandt": "fisheye"}


def canonical_model_name(model: str) -> str:
    """Canonical name of ``model`` (aliases resolved, case-insensitive); ValueError if unknown."""
    name = str(model).strip().lower()
    name = MODEL_ALIASES.get(name, name)
    if name not in _SPECS:
        known = ", ".join([*CAMERA_MODELS, *MODEL_ALIASES])
        raise ValueError(f"unknown camera model {model!r}; expected one of: {known}")
    return name


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A calibrated camera: model name, flat parameters and image size.

    Build it with :func:`create_camera` (which validates), :func:`camera_from_opencv` or
    :func:`camera_from_camera_info`. Instances are immutable and cheap to copy.

    Attributes
    ----------
    model : str
        Canonical model name, one of :data:`CAMERA_MODELS`.
    intrinsics : ndarray of shape (n_intrinsics,), float64
    distortion_coeffs : ndarray of shape (n_distortion,), float64
    width, height : int
        Image size in pixels.
    """

    model: str
    intrinsics: np.ndarray
    distortion_coeffs: np.ndarray
    width: int
    height: int
    params: np.ndarray = field(repr=False)

    # ---------------------------------------------------------------- construction / identity
    @property
    def model_id(self) -> int:
        """Integer id of the model for the kernels in :mod:`nbcalib.kernels.projection`."""
        return _SPECS[self.model].model_id

    @property
    def K(self) -> np.ndarray:
        """The 3 x 3 intrinsic matrix (models with fx, fy, cx, cy; not equirectangular)."""
        if self.model == "equirectangular":
            raise ValueError("an equirectangular camera has no intrinsic matrix K")
        fx, fy, cx, cy = self.intrinsics[:4]
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    def to_dict(self) -> dict:
        """JSON-ready ``{camera_model, intrinsics, distortion_coeffs, width, height}``."""
        return {
            "camera_model": self.model,
            "intrinsics": [float(x) for x in self.intrinsics],
            "distortion_coeffs": [float(x) for x in self.distortion_coeffs],
            "width": int(self.width),
            "height": int(self.height),
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> CameraModel:
        """Inverse of :meth:`to_dict` (``width``/``height`` required)."""
        missing = [k for k in ("camera_model", "intrinsics", "width", "height") if k not in d]
        if missing:
            raise ValueError(f"camera description lacks {', '.join(missing)}")
        return create_camera(
            d["camera_model"],
            d["intrinsics"],
            d.get("distortion_coeffs", []),
            d["width"],
            d["height"],
        )

    def __eq__(self, other) -> bool:
        if not isinstance(other, CameraModel):
            return NotImplemented
        return (
            self.model == other.model
            and (self.width, self.height) == (other.width, other.height)
            and np.array_equal(self.intrinsics, other.intrinsics)
            and np.array_equal(self.distortion_coeffs, other.distortion_coeffs)
        )

    def __hash__(self) -> int:
        return hash((self.model, self.width, self.height, self.params.tobytes()))

    def __repr__(self) -> str:
        intr = ", ".join(f"{x:.6g}" for x in self.intrinsics)
        dist = ", ".join(f"{x:.6g}" for x in self.distortion_coeffs)
        return (
            f"CameraModel({self.model!r}, intrinsics=[{intr}], distortion_coeffs=[{dist}], "
            f"width={self.width}, height={self.height})"
        )

    # ---------------------------------------------------------------- geometry
    def project(self, points_camera, *, in_image: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Project camera-frame points to pixels. Wraps ``kernels.projection_batch._project``.

        Parameters
        ----------
        points_camera : array_like of shape (N, 3) or (3,), float
            Points in the camera optical frame (x right, y down, z forward), metres.
        in_image : bool, optional
            Also require the pixel to lie in the image (``-0.5 <= u < W - 0.5``, same for v).

        Returns
        -------
        uv : ndarray of shape (N, 2), float64
            Pixel positions (u = column, v = row; pixel centres at integers). NaN where invalid.
        valid : ndarray of shape (N,), bool
            False for points behind the camera, outside the model's domain or non-finite.
        """
        pts, single = _as_points(points_camera)
        uv, valid = _kb._project(self.model_id, self.params, pts)
        if in_image:
            valid &= self.in_image(uv)
        return (uv[0], valid[0]) if single else (uv, valid)

    def project_jacobian(self, points_camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project points and return ``d(u, v) / d(x, y, z)``. Wraps ``_project_jacobian``.

        Returns
        -------
        uv : ndarray of shape (N, 2), float64
        jacobian : ndarray of shape (N, 2, 3), float64
            Derivative of the pixel with respect to the camera-frame point (pixels per metre).
        valid : ndarray of shape (N,), bool
        """
        pts, single = _as_points(points_camera)
        uv, jac, valid = _kb._project_jacobian(self.model_id, self.params, pts)
        return (uv[0], jac[0], valid[0]) if single else (uv, jac, valid)

    def intrinsics_jacobian(self, points_camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project points and return ``d(u, v) / d(fx, fy, cx, cy)``, exact for every model.

        Every model with a focal length maps a point to normalised, distorted coordinates
        ``(mx, my)`` by its lens alone and then to ``u = fx mx + cx``, ``v = fy my + cy``: the
        derivative is ``[[mx, 0, 1, 0], [0, my, 0, 1]]`` whatever the lens, with
        ``mx = (u - cx) / fx`` (the distortion and omnidir's ``xi`` act before ``K``). What
        refining the focal length and the principal point with the extrinsic needs (issue 47).

        Returns
        -------
        uv : ndarray of shape (N, 2), float64
        jacobian : ndarray of shape (N, 2, 4), float64
            Pixels per unit of ``fx``, ``fy`` (pixels per pixel of focal length) and per pixel
            of ``cx``, ``cy``.
        valid : ndarray of shape (N,), bool

        Raises
        ------
        ValueError
            For the equirectangular model, whose intrinsics are its image size.
        """
        if self.model == "equirectangular":
            raise ValueError("an equirectangular camera has no focal length or principal point")
        uv, valid = self.project(points_camera)
        fx, fy, cx, cy = self.intrinsics[:4]
        flat = np.atleast_2d(uv)
        jac = np.zeros((len(flat), 2, 4))
        jac[:, 0, 0] = (flat[:, 0] - cx) / fx
        jac[:, 1, 1] = (flat[:, 1] - cy) / fy
        jac[:, 0, 2] = jac[:, 1, 3] = 1.0
        return (uv, jac[0], valid) if np.ndim(uv) == 1 else (uv, jac, valid)

    def unproject(self, uv) -> np.ndarray:
        """Unit bearing vectors of pixel positions. Wraps ``kernels.unprojection._unproject``.

        Parameters
        ----------
        uv : array_like of shape (N, 2) or (2,), float
            Pixel positions (u = column, v = row).

        Returns
        -------
        bearings : ndarray of shape (N, 3), float64
            Unit vectors in the camera frame; NaN rows for pixels outside the model's domain.
        """
        arr = np.asarray(uv, dtype=np.float64)
        single = arr.ndim == 1
        arr = np.ascontiguousarray(arr.reshape(1, -1) if single else arr)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"uv must have shape (N, 2), got {np.shape(uv)}")
        bearings, _ = _ku._unproject(self.model_id, self.params, arr)
        return bearings[0] if single else bearings

    def in_image(self, uv) -> np.ndarray:
        """True where a pixel position lies inside the image (docs/conventions.md section 6)."""
        uv = np.asarray(uv, dtype=np.float64)
        u, v = uv[..., 0], uv[..., 1]
        return (u >= -0.5) & (u < self.width - 0.5) & (v >= -0.5) & (v < self.height - 0.5)

    def pixel_grid(self, step: int = 1) -> np.ndarray:
        """Centres of every ``step``-th pixel, shape (H' * W', 2), row-major (v slow, u fast)."""
        us = np.arange(0, self.width, step, dtype=np.float64)
        vs = np.arange(0, self.height, step, dtype=np.float64)
        uu, vv = np.meshgrid(us, vs)
        return np.stack([uu.ravel(), vv.ravel()], axis=1)

    @functools.cached_property
    def max_angle_rad(self) -> float:
        """Largest angle between the optical axis and the bearing of any pixel of the image."""
        n = 257
        us = np.linspace(-0.5, self.width - 0.5 - 1e-9, n)
        vs = np.linspace(-0.5, self.height - 0.5 - 1e-9, n)
        uu, vv = np.meshgrid(us, vs)
        bearings = self.unproject(np.stack([uu.ravel(), vv.ravel()], axis=1))
        z = bearings[:, 2]
        z = z[np.isfinite(z)]
        return float(np.arccos(np.clip(z.min(), -1.0, 1.0))) if z.size else 0.0

    @property
    def fov_deg(self) -> float:
        """Full field of view in degrees: twice :attr:`max_angle_rad`, at most 360."""
        return min(360.0, 2.0 * math.degrees(self.max_angle_rad))


# ------------------------------------------------------------------------------- factories


def offset_intrinsics(
    camera: CameraModel,
    *,
    focal_scale: float = 1.0,
    center_shift=(0.0, 0.0),
    distortion_scale: float = 1.0,
) -> CameraModel:
    """``camera`` with its focal length scaled, its principal point moved, its distortion scaled.

    ``fx, fy`` times ``focal_scale``, ``cx, cy`` plus ``center_shift`` pixels, every distortion
    coefficient times ``distortion_scale``; models with a focal length (omnidir's ``xi`` kept).
    """
    if camera.model == "equirectangular":
        raise ValueError("an equirectangular camera has no focal length or principal point")
    intrinsics = np.array(camera.intrinsics, dtype=np.float64)
    intrinsics[:2] *= focal_scale
    intrinsics[2:4] += center_shift
    distortion = np.asarray(camera.distortion_coeffs, dtype=np.float64) * distortion_scale
    return create_camera(camera.model, intrinsics, distortion, camera.width, camera.height)


def create_camera(
    model: str,
    intrinsics: Sequence[float],
    distortion_coeffs: Sequence[float] | None,
    width: int,
    height: int,
) -> CameraModel:
    """Create and validate a camera model.

    Parameters
    ----------
    model : str
        One of :data:`CAMERA_MODELS` (or an alias such as ``"equidistant"``).
    intrinsics : sequence of float
        The model's intrinsic parameters (table in the module docstring).
    distortion_coeffs : sequence of float or None
        The model's distortion coefficients, exactly as many as it has; empty or None means all 0.
    width, height : int
        Image size in pixels.

    Raises
    ------
    ValueError
        Unknown model, wrong number of parameters, non-finite or non-positive focal lengths,
        invalid image size. The message names the model and what it expected.
    """
    name = canonical_model_name(model)
    spec = _SPECS[name]
    intr = _as_flat("intrinsics", intrinsics, name)
    dist = _as_flat(
        "distortion_coeffs", [] if distortion_coeffs is None else distortion_coeffs, name
    )
    n_i, n_d = len(spec.intrinsic_names), len(spec.distortion_names)
    if intr.size != n_i:
        raise ValueError(
            f"camera model {name!r} takes {n_i} intrinsics "
            f"[{', '.join(spec.intrinsic_names)}], got {intr.size}"
        )
    if dist.size == 0:
        dist = np.zeros(n_d)
    if dist.size != n_d:
        expected = f"[{', '.join(spec.distortion_names)}]" if n_d else "none"
        raise ValueError(
            f"camera model {name!r} takes {n_d} distortion coefficients {expected}, got {dist.size}"
        )
    try:
        w, h = int(width), int(height)
    except (TypeError, ValueError):
        raise ValueError(f"camera model {name!r}: width and height must be integers") from None
    if w != width or h != height or w <= 0 or h <= 0:
        raise ValueError(
            f"camera model {name!r}: image size must be positive integers, got {width} x {height}"
        )

    if name == "equirectangular":
        if intr[0] != w or intr[1] != h:
            raise ValueError(
                f"camera model 'equirectangular' takes intrinsics [W, H] equal to the image "
                f"size {w} x {h}, got {intr.tolist()}"
            )
    else:
        fx, fy = intr[0], intr[1]
        if not (fx > 0 and fy > 0):
            raise ValueError(f"camera model {name!r}: focal lengths must be > 0, got {fx}, {fy}")
    if name == "omnidir" and not intr[4] >= 0:
        raise ValueError(f"camera model 'omnidir': xi must be >= 0, got {intr[4]}")
    if name == "atan" and not 0 <= dist[0] < math.pi:
        raise ValueError(f"camera model 'atan': omega must be in [0, pi), got {dist[0]}")

    params = np.zeros(_k.N_PARAMS)
    if name == "equirectangular":
        params[_k.P_WIDTH], params[_k.P_HEIGHT] = w, h
    else:
        params[: intr.size] = intr
        params[_k.P_DIST : _k.P_DIST + dist.size] = dist
        params[_k.P_WIDTH], params[_k.P_HEIGHT] = w, h
    params[_k.P_LIMIT] = _domain_limit(name, dist)
    intr.setflags(write=False)
    dist.setflags(write=False)
    params.setflags(write=False)
    return CameraModel(name, intr, dist, w, h, params)


def camera_from_opencv(K, D, width: int, height: int, *, fisheye: bool = False) -> CameraModel:
    """Camera from an OpenCV intrinsic matrix and distortion vector.

    ``D`` with 0, 4, 5 or 8 coefficients gives pinhole, plumb_bob (k3 = 0), plumb_bob or
    rational_polynomial; 12 or 14 are accepted when the thin-prism / tilt terms are zero.
    With ``fisheye=True``, ``D`` holds the 4 cv2.fisheye coefficients.
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"K must be 3 x 3, got shape {K.shape}")
    if K[0, 1] != 0.0 or not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
        raise ValueError("K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)")
    intr = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    d = np.asarray([] if D is None else D, dtype=np.float64).ravel()
    if fisheye:
        return create_camera("fisheye", intr, d, width, height)
    if d.size == 0 or not np.any(d):
        return create_camera("pinhole", intr, [], width, height)
    if d.size == 4:
        return create_camera("plumb_bob", intr, [*d, 0.0], width, height)
    if d.size == 5:
        return create_camera("plumb_bob", intr, d, width, height)
    if d.size in (8, 12, 14):
        if np.any(d[8:]):
            raise ValueError("OpenCV thin-prism / tilted-sensor distortion terms are not supported")
        if not np.any(d[5:8]):
            return create_camera("plumb_bob", intr, d[:5], width, height)
        return create_camera("rational_polynomial", intr, d[:8], width, height)
    raise ValueError(
        f"OpenCV distortion vector must have 0, 4, 5, 8, 12 or 14 entries, got {d.size}"
    )


#: ROS CameraInfo distortion_model names for the models ROS knows.
_ROS_MODEL_NAMES = {
    "plumb_bob": "plumb_bob",
    "rational_polynomial": "rational_polynomial",
    "fisheye": "equidistant",
    "pinhole": "plumb_bob",
}


def camera_from_camera_info(
    msg=None,
    *,
    width: int | None = None,
    height: int | None = None,
    distortion_model: str | None = None,
    D=None,
    K=None,
) -> CameraModel:
    """Camera from a ROS ``sensor_msgs/CameraInfo`` message or its fields.

    Pass a message object (ROS1 ``D``/``K`` or ROS2 ``d``/``k`` attributes, e.g. from rosbags) or
    the fields as keywords. ``distortion_model`` ``plumb_bob``, ``rational_polynomial`` and
    ``equidistant`` map to nbcalib's models; for models CameraInfo cannot name, nbcalib writes its
    own model name with ``D`` = distortion coefficients, and for ``omnidir`` ``D = [xi, k1, k2,
    p1, p2]`` (see :func:`camera_to_camera_info`).
    """
    if msg is not None:
        width = msg.width if width is None else width
        height = msg.height if height is None else height
        distortion_model = msg.distortion_model if distortion_model is None else distortion_model
        D = _first_attr(msg, ("d", "D")) if D is None else D
        K = _first_attr(msg, ("k", "K")) if K is None else K
    if width is None or height is None or K is None:
        raise ValueError("camera info needs width, height and K")
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    d = np.asarray([] if D is None else D, dtype=np.float64).ravel()
    model = (distortion_model or "").strip().lower()
    if model == "":
        model = "pinhole" if not np.any(d) else "plumb_bob"
    name = canonical_model_name(model)
    intr = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    n_d = len(_SPECS[name].distortion_names)
    if name == "omnidir":
        if d.size != 5:
            raise ValueError(
                f"omnidir camera info must have D = [xi, k1, k2, p1, p2], got {d.size}"
            )
        return create_camera("omnidir", [*intr, d[0]], d[1:], width, height)
    if name == "equirectangular":
        return create_camera(name, [width, height], [], width, height)
    if d.size > n_d and not np.any(d[n_d:]):
        d = d[:n_d]  # drivers often pad D with zeros (e.g. 8 entries for plumb_bob)
    return create_camera(name, intr, d, width, height)


def camera_to_camera_info(camera: CameraModel) -> dict:
    """Fields of a ROS ``sensor_msgs/CameraInfo`` for ``camera`` (inverse of the function above).

    Returns ``{"width", "height", "distortion_model", "D", "K", "R", "P"}`` with ``K``, ``R`` (3x3)
    and ``P`` (3x4) as flat row-major lists.
    """
    m = camera.model
    if m == "equirectangular":
        K = np.eye(3)
        D = []
    else:
        K = camera.K
        D = list(camera.distortion_coeffs)
        if m == "omnidir":
            D = [float(camera.intrinsics[4]), *D]
        if m == "pinhole":
            D = [0.0] * 5
    P = np.hstack([K, np.zeros((3, 1))])
    return {
        "width": int(camera.width),
        "height": int(camera.height),
        "distortion_model": _ROS_MODEL_NAMES.get(m, m),
        "D": [float(x) for x in D],
        "K": [float(x) for x in K.ravel()],
        "R": [float(x) for x in np.eye(3).ravel()],
        "P": [float(x) for x in P.ravel()],
    }


# ------------------------------------------------------------------------------- helpers


def _first_attr(obj, names):
    for n in names:
        if hasattr(obj, n):
            return getattr(obj, n)
    return None


def _as_flat(what: str, values, model: str) -> np.ndarray:
    try:
        arr = np.array(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError(
            f"camera model {model!r}: {what} must be numbers, got {values!r}"
        ) from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"camera model {model!r}: {what} must be finite, got {arr.tolist()}")
    return arr


def _as_points(points) -> tuple[np.ndarray, bool]:
    arr = np.asarray(points, dtype=np.float64)
    single = arr.ndim == 1
    if single:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {np.shape(points)}")
    return np.ascontiguousarray(arr), single


def _first_root(cond, hi: float) -> float:
    """Smallest x in (0, hi] where ``cond`` (vectorised, True near 0) turns False, else inf."""
    grid = np.concatenate(
        [np.linspace(0.0, min(hi, 10.0), 20001)[1:], np.geomspace(10.0, hi, 4001)]
    )
    grid = grid[grid <= hi]
    ok = cond(grid)
    bad = np.flatnonzero(~ok)
    if bad.size == 0:
        return math.inf
    i = bad[0]
    lo, up = (grid[i - 1] if i > 0 else 0.0), grid[i]
    for _ in range(100):
        mid = 0.5 * (lo + up)
        if cond(np.array([mid]))[0]:
            lo = mid
        else:
            up = mid
    return lo


def _domain_limit(name: str, dist: np.ndarray) -> float:
    """Where the distortion stops being monotonic (see ``params[P_LIMIT]`` in the kernels)."""
    if name in ("pinhole", "atan", "equirectangular"):
        return math.inf
    if name == "fisheye":
        k1, k2, k3, k4 = dist

        def increasing(t):
            t2 = t * t
            return 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4))) > 0

        return min(_first_root(increasing, math.pi), math.pi)
    d = np.zeros(8)
    if name == "omnidir":
        d[:4] = dist  # k1 k2 p1 p2
    else:
        d[: dist.size] = dist
    k1, k2, _, _, k3, k4, k5, k6 = d

    def monotonic(r):
        r2 = r * r
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        with np.errstate(all="ignore"):
            rad = num / den
            drad = (dnum * den - num * dden) / (den * den)
            return (den > 0) & (rad > 0) & (rad + 2 * r2 * drad > 0)

    r = _first_root(monotonic, 1e4)
    return r * r


#: A realistic camera per model (used by ``nbcalib selfcheck``, examples and synthetic rigs).
_EXAMPLES = {
    "pinhole": ([720.0, 720.0, 639.5, 479.5], []),
    "plumb_bob": ([900.0, 902.0, 641.3, 478.2], [-0.25, 0.08, 0.0012, -0.0005, -0.01]),
    "rational_polynomial": (
        [700.0, 700.0, 639.5, 479.5],
        [2.0, 0.5, 0.0005, -0.0003, 0.01, 2.3, 0.9, 0.05],
    ),
    "fisheye": ([380.0, 381.0, 639.5, 479.5], [0.05, -0.01, 0.002, -0.0005]),
    "atan": ([560.0, 560.0, 639.5, 479.5], [0.9]),
    "omnidir": ([700.0, 702.0, 639.5, 479.5, 1.2], [-0.2, 0.05, 0.001, 0.0005]),
    "equirectangular": (None, []),
}


def example_camera(model: str, width: int = 1280, height: int = 960) -> CameraModel:
    """A realistic camera of ``model`` for a ``width`` x ``height`` image (1280 x 960 default).

    Focal lengths and principal points scale with the image width; the distortion is that of a
    typical lens of the kind (barrel for plumb_bob, a wide-angle rational lens, a full-frame
    fisheye, a Mei-model omnidirectional lens). An equirectangular camera gets a 2:1 image of the
    given width.
    """
    name = canonical_model_name(model)
    intr, dist = _EXAMPLES[name]
    if name == "equirectangular":
        return create_camera(name, [width, width // 2], [], width, width // 2)
    s = width / 1280.0
    intr = np.array(intr, dtype=np.float64)
    intr[:2] *= s
    intr[2] = (intr[2] + 0.5) * s - 0.5
    intr[3] = (intr[3] + 0.5) * (height / 960.0) - 0.5
    return create_camera(name, intr, dist, width, height)
