"""Settings of keypoint matching (paper section III-D, first step), importable without numba.

:class:`MatchConfig` is the ``matching`` section of the pipeline's config
(:class:`nbcalib.config.CalibrationConfig`): :func:`nbcalib.matching.match_images` and
:func:`nbcalib.matching.find_correspondences` take their defaults from it, and so do the command
line and config files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["LEARNED_MATCHER_NAMES", "MATCHER_CHOICES", "NORMALIZATIONS", "ROTATIONS", "MatchConfig"]

#: Learned matchers, best first (ONNX graphs exported by ``nbcalib models export``).
LEARNED_MATCHER_NAMES = ("xfeat-lighterglue", "aliked-lightglue", "disk-lightglue")
#: Values of :attr:`MatchConfig.matcher`: ``auto`` picks the best exported one, else SIFT.
MATCHER_CHOICES = ("auto", *LEARNED_MATCHER_NAMES, "sift")
#: Image normalisations (:mod:`nbcalib.matching.normalize`).
NORMALIZATIONS = ("none", "equalize", "clahe", "invert", "gradient")
#: Clockwise image rotations before matching, degrees.
ROTATIONS = (0, 90, 180, 270)


@dataclass(frozen=True)
class MatchConfig:
    """How the camera image is matched with the LiDAR data and lifted to 2D-3D pairs.

    Attributes
    ----------
    matcher : str
        ``auto`` (the best exported learned matcher, else ``sift``), a learned matcher of
        `LEARNED_MATCHER_NAMES`, or ``sift``.
    match_threshold : float
        Minimum match probability of a learned matcher (the reference's 0.01; the paper 0.05).
    rotate_camera, rotate_lidar : int
        Clockwise rotation of the camera / LiDAR image before matching (0, 90, 180, 270), e.g.
        for a camera mounted upside down; keypoints are returned in the unrotated images.
    camera_normalization, lidar_normalization : str
        Image normalisation before matching (:data:`NORMALIZATIONS`): ``gradient`` (the
        magnitude of the Sobel gradient) removes the sign of an edge, which differs between
        reflectivity and brightness (docs/BENCHMARKS.md, "Matching").
    camera_scale : float or None
        Resample the camera image by this factor before matching a stored LiDAR image
        (``views == 0``); None: the ratio of the two images' pixels per degree, so that both
        have the same scale (the matchers are not invariant to a scale change of 2 or more).
    max_image_side : int or None
        Shrink both images by one common factor so that no side is longer, pixels (None: no
        limit). The learned extractors' memory grows with the pixel count.
    fill_radius : int
        Fill empty LiDAR-image pixels from filled ones this close before matching, pixels.
    detection_threshold : float or None
        Keypoint score threshold of a learned extractor (None: the model's own).
    max_keypoints : int or None
        Keypoints per image at most (the strongest; None: all the model returns), in the
        heading sweep. LighterGlue's attention grows with the square of the keypoints (1.3 s a
        view at 2048 on the 2-core machine, 0.5 s at 1024: find-matches 20.6 -> 7.0 s), but
        1024 left one synthetic guess of 39 at 1.08 deg, flagged ok, so the default stays 2048
        (docs/BENCHMARKS.md, section 10).
    sift_ratio : float
        Lowe's ratio of the SIFT fallback.
    threads : int or None
        onnxruntime intra-op threads (None: the number of cores, one fewer while a first run
        compiles kernels in the background, :func:`nbcalib.warmup.running`).
    views : int
        Camera-shaped LiDAR views: the dense cloud is rendered through the real camera's model
        at the LiDAR's angular resolution, at ``views`` level headings around the LiDAR (or a
        few orientations around a prior), and the view with the most rotation-only RANSAC
        inliers is kept (:mod:`nbcalib.matching.multiview`). 0: match the stored LiDAR image of
        preprocessing instead, as the reference toolbox does.
    screen_views : int
        When there are more views than this, every view is first matched by its descriptors'
        mutual nearest neighbours (a tenth of LighterGlue's second a view) and the learned
        matcher runs on this many, those with the most RANSAC support of the screen, and on
        every view whose screened rotation agrees with the first's as the pool asks (0: the
        matcher on every view; SIFT always matches every view). The best and pooled views
        are chosen among these (docs/BENCHMARKS.md, section 10).
    matched_views : int
        At most this many of the screened views go to the learned matcher, those with the most
        RANSAC support of the screen (0: no limit). A wide camera's screened rotations agree
        in most views, and all of those would go.
    prior_yaw_offsets_deg : tuple of float
        Yaw offsets of the views around a prior, degrees.
    pixels_per_degree : float or None
        Angular resolution of the views (None:
        :data:`~nbcalib.matching.views.DEFAULT_PIXELS_PER_DEGREE`; never above the camera's).
    min_fill : float
        Views with a smaller fraction of filled pixels are not matched.
    splat_pixels_at_1m : float
        Range-dependent splat of the views (0: off; :func:`~nbcalib.matching.views.render_view`).
    median : int
        Median filter of the view intensities, pixels (0: off).
    inpaint_deg : float
        Inpaint the holes of each view's LiDAR coverage up to this wide, degrees (0: off;
        :func:`~nbcalib.matching.views.inpaint_coverage`).
    retry_pixels_per_degree : tuple of float
        When a pair's views give no initial guess that passes its success test, match them
        again at each of these resolutions in turn (pixels per degree, never above the
        camera's), with the LiDAR coverage inpainted (``retry_inpaint_deg``), until one does;
        the attempt with the best guess is kept (:func:`~nbcalib.matching.find.
        find_correspondences`). () : no retries. Real scans are sparse rings that the learned
        matchers do not match to a photograph until the gaps are filled and the view is
        finer than the LiDAR's own resolution (docs/BENCHMARKS.md, "Initial guess on real
        data").
    retry_inpaint_deg : float
        ``inpaint_deg`` of the retries.
    lift_inpainted : bool
        A keypoint on an inpainted pixel of a view takes the nearest LiDAR point within half
        the inpainted width (True), or within ``search_radius`` like any other (False: those
        far from a point are dropped). Half an inpainted width is a degree: the points lifted
        that far bias a pose pooled over many frames (KITTI odometry: 58 cm / 1.2 deg against
        13 cm / 0.3 deg; docs/BENCHMARKS.md), so the frames of a recording are lifted tightly.
    fine_max_keypoints : int or None
        ``max_keypoints`` of the finer matching (2048): the refined view (``refine_view``) and
        the retries, so that a faster sweep (``max_keypoints`` 1024) keeps them: the sparse
        real scans that need a retry lose good guesses with fewer keypoints (2 of 3 refused
        with 1024 everywhere in the real-data benchmark, none with the retries at 2048).
    search_radius : float
        A LiDAR keypoint on an empty pixel takes the nearest LiDAR point within this radius,
        pixels (raised to ``fill_radius`` for the views, whose holes are filled).
    view_ransac_iterations : int
        Rotation-only RANSAC hypotheses that score one view (its inlier threshold is the
        initial guess's ``ransac_threshold``).
    pool : bool
        Add the correspondences of views whose RANSAC rotation agrees with the best view's.
    pool_angle_deg : float
        Agreement of two views' RANSAC rotations, degrees.
    min_pool_support : int
        RANSAC inliers a view needs to be pooled.
    guess_pairs : int
        A job of several pairs (the frames of a recording, :mod:`nbcalib.matching.recording`)
        matches its frames in turn until the pose pooled from their matches is found, stops
        moving as frames are added, and this many frames agree with it (``min_pool_support``
        inliers each); the rest are not matched, and the initial guess is estimated from the
        matched ones (0: every frame is matched).
    frames_pixels_per_degree : float
        When the views as configured let a recording's frames find no pose, they are screened
        and matched again at this resolution (never above the camera's)...
    frames_inpaint_deg : float
        ... with the LiDAR coverage's gaps up to this wide inpainted and keypoints lifted
        tightly (:func:`~nbcalib.matching.recording.attempt_settings`): the finer views sparse
        real scans need.
    refine_view : bool
        Estimate the pose from the kept correspondences and, when that succeeds, render and
        match one more view from that pose (no parallax left).
    draw : bool
        Write ``<name>_matches.png`` (the matches drawn) into the work directory.
    """

    matcher: str = "auto"
    match_threshold: float = 0.01
    rotate_camera: int = 0
    rotate_lidar: int = 0
    camera_normalization: str = "gradient"
    lidar_normalization: str = "gradient"
    camera_scale: float | None = None
    max_image_side: int | None = 2048
    fill_radius: int = 2
    detection_threshold: float | None = None
    max_keypoints: int | None = 2048
    sift_ratio: float = 0.8
    threads: int | None = None
    views: int = 12
    screen_views: int = 4
    matched_views: int = 0
    prior_yaw_offsets_deg: tuple[float, ...] = (-20.0, 0.0, 20.0)
    pixels_per_degree: float | None = None
    min_fill: float = 0.05
    splat_pixels_at_1m: float = 0.0
    median: int = 0
    inpaint_deg: float = 0.0
    retry_pixels_per_degree: tuple[float, ...] = (10.0, 15.0)
    retry_inpaint_deg: float = 2.0
    lift_inpainted: bool = True
    fine_max_keypoints: int | None = 2048
    search_radius: float = 2.0
    view_ransac_iterations: int = 2048
    pool: bool = True
    pool_angle_deg: float = 2.0
    min_pool_support: int = 6
    guess_pairs: int = 2
    frames_pixels_per_degree: float = 10.0
    frames_inpaint_deg: float = 2.0
    refine_view: bool = True
    draw: bool = True

    def __post_init__(self):
        object.__setattr__(
            self, "prior_yaw_offsets_deg", tuple(float(v) for v in self.prior_yaw_offsets_deg)
        )
        object.__setattr__(
            self, "retry_pixels_per_degree", tuple(float(v) for v in self.retry_pixels_per_degree)
        )
        for value in self.retry_pixels_per_degree:
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"retry_pixels_per_degree must hold numbers > 0, got {value}")
        if self.matcher not in MATCHER_CHOICES:
            raise ValueError(
                f"matcher must be one of {', '.join(MATCHER_CHOICES)}, got {self.matcher!r}"
            )
        for name in ("camera_normalization", "lidar_normalization"):
            value = getattr(self, name)
            if value not in NORMALIZATIONS:
                raise ValueError(
                    f"{name} must be one of {', '.join(NORMALIZATIONS)}, got {value!r}"
                )
        for name in ("rotate_camera", "rotate_lidar"):
            if getattr(self, name) not in ROTATIONS:
                raise ValueError(f"{name} must be 0, 90, 180 or 270, got {getattr(self, name)!r}")
        if not math.isfinite(self.match_threshold):
            raise ValueError(f"match_threshold must be finite, got {self.match_threshold}")
        if self.camera_scale is not None and not (
            math.isfinite(self.camera_scale) and 0.05 <= self.camera_scale <= 20.0
        ):
            raise ValueError(f"camera_scale must be in [0.05, 20], got {self.camera_scale}")
        if self.max_image_side is not None and self.max_image_side < 16:
            raise ValueError(f"max_image_side must be >= 16, got {self.max_image_side}")
        for name in ("max_keypoints", "fine_max_keypoints"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise ValueError(f"{name} must be >= 1, got {value}")
        for name in (
            "fill_radius",
            "median",
            "views",
            "screen_views",
            "matched_views",
            "guess_pairs",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("search_radius", "splat_pixels_at_1m", "pool_angle_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if not 0.0 <= self.min_fill <= 1.0:
            raise ValueError(f"min_fill must be in [0, 1], got {self.min_fill}")
        if not 0.0 < self.sift_ratio <= 1.0:
            raise ValueError(f"sift_ratio must be in (0, 1], got {self.sift_ratio}")
        if self.view_ransac_iterations < 1 or self.min_pool_support < 1:
            raise ValueError("view_ransac_iterations and min_pool_support must be >= 1")
        if not (math.isfinite(self.frames_pixels_per_degree) and self.frames_pixels_per_degree > 0):
            raise ValueError(
                f"frames_pixels_per_degree must be > 0, got {self.frames_pixels_per_degree}"
            )
        for name in ("inpaint_deg", "retry_inpaint_deg", "frames_inpaint_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if self.pixels_per_degree is not None and not self.pixels_per_degree > 0:
            raise ValueError(f"pixels_per_degree must be > 0, got {self.pixels_per_degree}")
        if self.threads is not None and self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
