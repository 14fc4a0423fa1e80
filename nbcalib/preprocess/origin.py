"""Where the LiDAR sits in its cloud's frame: taken, or found from the rings of a spinning scan.

A cloud is usually in its LiDAR's own frame, the sensor at the origin; but recordings also give
clouds in a vehicle frame (Waymo: the ground at z = 0, the roof LiDAR about 2 m above the
origin) or a map frame. Whatever looks *from the sensor* then looks from the wrong place: the
camera-shaped views matching renders, the virtual camera's LiDAR image and rotation-only
RANSAC's bearings, which assume the camera near the LiDAR. On the Waymo frames every view was
rendered 2 m below the roof and the matches found no pose; rendered from the roof the same
frames gave a guess fine registration took to 0.11 deg / 5.6 cm (issue 45).

**Found.** Each beam of a spinning LiDAR keeps one elevation: seen from the sensor, the points'
elevations fall into a few dozen sharp rings; seen from elsewhere, a near point's elevation
moves by its offset over its distance and the rings blur. :func:`ring_spread` measures how
sharp they are: the entropy of the elevations in fine bins *within* bins eight times wider (the
information the fine bins add to the coarse ones: 0 when every coarse bin holds one sharp ring,
``log 8`` when the elevations are spread evenly), which does not reward an origin that merely
squeezes every elevation into a narrow band the way the plain entropy does
(:mod:`nbcalib.kernels.origin`). :func:`find_lidar_origin` searches a box around the cloud's
origin for the sharpest rings: a grid every 25 cm across and 10 cm in height (the rings' dip
is only a few decimetres wide), then a finer grid around the best.

**Used** (:func:`choose_lidar_origin`) only when it is clearly elsewhere: at least
:data:`MIN_OFFSET` from the cloud's origin (a sensor's own frame can sit a little off its rings:
KITTI's HDL-64 rings are sharpest 0.2 m above its frame, an Ouster's lidar and sensor frames
differ by 4 cm; rendering from there changes nothing), sharper by :data:`MIN_GAIN` there than
at the cloud's origin, not on the search box's edge, and, over several scans, found at the same
place. A scan without rings (a non-repetitive Livox) keeps its origin.

The origin is the virtual camera's position (:class:`nbcalib.products.VirtualCamera`), from
which the LiDAR image and matching's views are rendered, and the point rotation-only RANSAC
takes the camera to be at (:func:`nbcalib.initial_guess.estimate_initial_guess`). The extrinsic
itself stays in the cloud's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "MIN_GAIN",
    "MIN_OFFSET",
    "LidarOrigin",
    "choose_lidar_origin",
    "find_lidar_origin",
    "lidar_origin",
    "ring_spread",
]

#: A found origin nearer than this to the cloud's origin is not used, metres.
MIN_OFFSET = 0.5
#: ... nor one whose rings are not sharper than near the cloud's origin by this fraction (the
#: Waymo frames: 10 %; scans in their sensor's frame: 0, nothing sharper elsewhere).
MIN_GAIN = 0.05
#: Points the coarse and the fine search score (seeded random subsets).
SEARCH_POINTS = (6_000, 20_000)
#: A scan covering less azimuth than this (degrees, from the cloud's origin) is not searched: it
#: is not a spinning LiDAR's (or is cut to a camera's view).
MIN_AZIMUTH_DEG = 180.0
#: The search box around the cloud's origin, metres: horizontal half-width, lowest and highest.
SEARCH_XY = 3.0
SEARCH_Z = (-1.0, 4.0)
#: Found origins of several scans agree within this distance, metres.
AGREE = 0.5
#: Points nearer than this (horizontally) to a candidate origin are left out, metres.
_MIN_DISTANCE = 1.0


@dataclass(frozen=True)
class LidarOrigin:
    """The LiDAR's position in its cloud's frame, and where it came from.

    Attributes
    ----------
    xyz : tuple of float
        Metres, in the frame of the clouds (``T_camera_lidar`` maps this frame).
    source : {"cloud", "found", "given"}
        The cloud's own origin (not moved), found from the rings, or set by the user.
    detail : str
        One line on how it was decided.
    """

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: str = "cloud"
    detail: str = ""

    @property
    def moved(self) -> bool:
        """The origin is not the cloud's own."""
        return any(v != 0.0 for v in self.xyz)

    def describe(self) -> str:
        """One line for the log."""
        if not self.moved:
            return (
                f"LiDAR origin: the cloud's own ({self.detail})"
                if self.detail
                else ("LiDAR origin: the cloud's own")
            )
        x, y, z = self.xyz
        return f"LiDAR origin: ({x:.2f}, {y:.2f}, {z:.2f}) m in the cloud's frame, {self.detail}"


#: Fine bins of the elevation's tangent (about 0.06 degrees near the horizon), fine bins per
#: coarse bin, and the largest tangent binned (60 degrees: beyond every spinning LiDAR's beams).
_WIDTH, _GROUP, _U_MAX = 0.001, 8, 1.75


def ring_spreads(points_lidar, xs, ys, zs) -> np.ndarray:
    """:func:`ring_spread` of every origin of the grid ``xs x ys x zs``, shape (X, Y, Z).

    Wraps :func:`nbcalib.kernels.origin._ring_spreads` (reference:
    :func:`nbcalib.reference.origin.ring_spread`).
    """
    from nbcalib.kernels.origin import _ring_spreads

    points = np.ascontiguousarray(points_lidar, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_lidar must have shape (N, 3), got {points.shape}")
    axes = [np.ascontiguousarray(np.atleast_1d(a), dtype=np.float64) for a in (xs, ys, zs)]
    if any(a.ndim != 1 or not np.all(np.isfinite(a)) for a in axes):
        raise ValueError("xs, ys and zs must be finite 1-D arrays")
    points = points[np.all(np.isfinite(points), axis=1)]
    out = np.empty(tuple(len(a) for a in axes))
    n_fine = (round(2.0 * _U_MAX / _WIDTH) // _GROUP) * _GROUP
    _ring_spreads(points, *axes, _WIDTH, n_fine, _GROUP, _U_MAX, _MIN_DISTANCE, out)
    return out


def ring_spread(points_lidar, origin=(0.0, 0.0, 0.0)) -> float:
    """How blurred a scan's rings look from ``origin`` (module docstring): 0 sharp.

    The entropy of the points' elevation tangents in fine bins (about 0.06 degrees) given the
    bins eight times wider, nats, in ``[0, log 8]``; points within 1 m horizontally of the origin
    or more than 60 degrees up or down count as spread out (``log 8``).

    Parameters
    ----------
    points_lidar : array_like of shape (N, 3)
        One scan, metres.
    origin : array_like of shape (3,), optional
        Where the elevations are measured from.
    """
    o = np.asarray(origin, dtype=np.float64)
    if o.shape != (3,):
        raise ValueError(f"origin must have shape (3,), got {o.shape}")
    return float(ring_spreads(points_lidar, o[:1], o[1:2], o[2:])[0, 0, 0])


def _best(points, xs, ys, zs) -> tuple[float, np.ndarray]:
    """The lowest spread over the grid ``xs x ys x zs``: (spread, origin)."""
    spreads = ring_spreads(points, xs, ys, zs)
    i, j, k = np.unravel_index(int(np.argmin(spreads)), spreads.shape)
    return float(spreads[i, j, k]), np.array([xs[i], ys[j], zs[k]], dtype=np.float64)


def find_lidar_origin(points_lidar, *, seed: int = 0) -> tuple[np.ndarray, float, float, bool]:
    """The place in a box around the cloud's origin from which the scan's rings look sharpest.

    Parameters
    ----------
    points_lidar : array_like of shape (N, 3)
        One scan of a spinning LiDAR, metres, in any frame whose origin lies within
        :data:`SEARCH_XY` horizontally and :data:`SEARCH_Z` vertically of the sensor.
    seed : int, optional
        Seed of the subsets scored.

    Returns
    -------
    origin : ndarray of shape (3,)
        Metres, in the cloud's frame.
    spread : float
        :func:`ring_spread` there.
    spread_at_zero : float
        The least :func:`ring_spread` within 0.3 m of the cloud's origin (the cloud in its
        sensor's frame).
    on_edge : bool
        The best lies on the search box's boundary (the true origin may lie beyond).
    """
    points = np.asarray(points_lidar, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_lidar must have shape (N, 3), got {points.shape}")
    points = points[np.all(np.isfinite(points), axis=1)]
    order = np.random.default_rng(seed).permutation(len(points))
    coarse = points[np.sort(order[: SEARCH_POINTS[0]])]
    points = points[np.sort(order[: SEARCH_POINTS[1]])]
    if len(points) < 100:
        at_zero = ring_spread(points)
        return np.zeros(3), at_zero, at_zero, False
    # the cloud's own origin as the sensor's: its sharpest rings within 0.3 m (a sensor's frame
    # can sit a little off its rings; indoors their dip is a few centimetres wide)
    near = np.arange(-0.3, 0.3 + 1e-9, 0.075)
    at_zero, _ = _best(coarse, near, near, np.arange(-0.3, 0.3 + 1e-9, 0.01))
    # elsewhere: every 0.25 m across, 10 cm in height (outdoors the dip is decimetres wide)
    xs = np.arange(-SEARCH_XY, SEARCH_XY + 1e-9, 0.25)
    zs = np.arange(SEARCH_Z[0], SEARCH_Z[1] + 1e-9, 0.1)
    coarse_spread, o = _best(coarse, xs, xs, zs)
    if coarse_spread >= at_zero:
        return np.zeros(3), at_zero, at_zero, False
    # then 5 cm across and 2 cm in height around the best, both on more points
    fine = np.arange(-0.3, 0.3 + 1e-9, 0.05)
    spread, o = _best(points, o[0] + fine, o[1] + fine, o[2] + np.arange(-0.16, 0.16 + 1e-9, 0.02))
    at_zero, _ = _best(points, near, near, np.arange(-0.3, 0.3 + 1e-9, 0.01))
    if spread >= at_zero:
        return np.zeros(3), at_zero, at_zero, False
    edge = (
        max(abs(o[0]), abs(o[1])) >= SEARCH_XY - 0.1
        or o[2] <= SEARCH_Z[0] + 0.1
        or o[2] >= SEARCH_Z[1] - 0.1
    )
    return o, spread, at_zero, bool(edge)


def azimuth_coverage_deg(points_lidar) -> float:
    """Degrees of azimuth (about the cloud's z, 1-degree bins) that hold a point."""
    points = np.asarray(points_lidar, dtype=np.float64)
    azimuth = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return float(np.unique(np.floor(azimuth).astype(np.int64)).size)


def choose_lidar_origin(scans, *, seed: int = 0, max_scans: int = 2) -> LidarOrigin:
    """The origin to use for the clouds of one recording, from a few of its raw scans.

    The first scan's :func:`find_lidar_origin`; when it places the origin elsewhere, the next
    scans' too (up to ``max_scans``). The origin moves only when every rule of the module
    docstring holds: a spinning scan (at least :data:`MIN_AZIMUTH_DEG` of azimuth), clearly
    away from the cloud's origin, clearly sharper, not on the search's edge, and, with several
    scans, found at the same place (within :data:`AGREE`) by most of them (their median is
    used).

    Parameters
    ----------
    scans : iterable of array_like of shape (N, 3)
        Raw scans in the clouds' frame (one per pair), read as needed.
    seed : int, optional
    max_scans : int, optional

    Returns
    -------
    LidarOrigin
    """
    finds = []
    for points in scans:
        if len(finds) >= max_scans or (finds and not finds[0][2]):
            break
        points = np.asarray(points, dtype=np.float64)
        if azimuth_coverage_deg(points) < MIN_AZIMUTH_DEG:
            return LidarOrigin(detail="not a spinning LiDAR's scan: no rings to search")
        o, spread, at_zero, edge = find_lidar_origin(points, seed=seed)
        gain = (at_zero - spread) / at_zero if at_zero > 0 else 0.0
        far = float(np.linalg.norm(o)) >= MIN_OFFSET
        finds.append((o, gain, far and gain >= MIN_GAIN and not edge))
    moved = [f for f in finds if f[2]]
    if not finds or not moved:
        return LidarOrigin(detail="its scan's rings are sharpest near it")
    centre = np.median(np.array([f[0] for f in moved]), axis=0)
    agree = [f for f in moved if np.linalg.norm(f[0] - centre) <= AGREE]
    if 2 * len(agree) <= len(finds) and len(finds) > 1:
        return LidarOrigin(
            detail=f"{len(moved)} of {len(finds)} scans place the rings' centre elsewhere, not "
            "at one place"
        )
    centre = np.median(np.array([f[0] for f in agree]), axis=0)
    gain = float(np.median([f[1] for f in agree]))
    xyz = tuple(round(float(v), 3) for v in centre)
    return LidarOrigin(
        xyz,
        "found",
        f"found: the scan's rings are {100 * gain:.1f} % sharper from there than from the "
        f"cloud's origin ({len(agree)} of {len(finds)} scan(s))",
    )


def lidar_origin(pairs, config) -> LidarOrigin:
    """The LiDAR origin of a job's pairs as ``config.lidar_origin`` says.

    Parameters
    ----------
    pairs : sequence of PairInput
        The job's pairs (:class:`nbcalib.preprocess.inputs.PairInput`): with ``"auto"``, the
        image's own scan of the first, middle and last pair are searched, as needed
        (:func:`choose_lidar_origin`).
    config : PreprocessConfig

    Returns
    -------
    LidarOrigin
    """
    given = config.given_origin()
    if given is not None:
        return LidarOrigin(tuple(given), "given", "given (preprocess.lidar_origin)")
    if str(config.lidar_origin).strip().lower() == "cloud" or not pairs:
        return LidarOrigin(detail="kept (preprocess.lidar_origin 'cloud')")
    order = list(dict.fromkeys([0, len(pairs) // 2, len(pairs) - 1]))
    scans = (pairs[k].scans[pairs[k].image_scan or 0].points for k in order if pairs[k].scans)
    return choose_lidar_origin(scans)
