"""Command-line options, mapped onto the config tree (:mod:`nbcalib.config`).

Each option names the setting it sets (``--voxel-size`` -> ``preprocess.voxel_size``); its
default and type come from that setting's dataclass, so no default is written here. Options are
added with ``argparse.SUPPRESS`` as default, so a namespace holds only what the user typed:
:func:`build_config` lays the command line over a config file over a base config (the defaults,
or the config a work directory recorded).

The same table reads config files whose keys are option names (``voxel-size = 0.01``,
``dynamic = true``), at the top level or in a stage's table (:func:`file_settings`).
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass, fields
from typing import Any

from nbcalib.config import SECTIONS, CalibrationConfig, _kind, renamed_settings, set_values
from nbcalib.errors import InputError

log = logging.getLogger("nbcalib")

__all__ = [
    "ASSESS",
    "INITIAL_GUESS",
    "INIT_UNCERTAINTY_HELP",
    "INPUT_OPTIONS",
    "MATCHING",
    "PREPROCESS",
    "RECORDING_OPTIONS",
    "REFINE",
    "RUN_OPTIONS",
    "Option",
    "add_options",
    "build_config",
    "file_settings",
    "flag_names",
    "flag_spelling",
    "given_settings",
]

_FLAG = object()


@dataclass(frozen=True)
class Option:
    """One command-line option and the setting it sets.

    Attributes
    ----------
    flag : str
        ``--voxel-size``.
    setting : str
        ``section.field`` (or ``seed``); empty for options that are not settings (inputs).
    help : str
        Help text; the default is appended from the setting.
    metavar : str, tuple of str or None
    value : object
        For options without an argument (``--dynamic``): the value they set.
    choices : tuple or None
        Allowed values (default: none, or the setting's own).
    """

    flag: str
    setting: str
    help: str
    metavar: str | tuple | None = None
    value: Any = _FLAG
    choices: tuple | None = None

    @property
    def dest(self) -> str:
        """Namespace attribute: the flag without dashes (``voxel_size``)."""
        return self.flag.lstrip("-").replace("-", "_")

    @property
    def takes_value(self) -> bool:
        """The option reads an argument (``--bins 8``), as opposed to a switch."""
        return self.value is _FLAG

    def default(self):
        """The setting's default (None for options that are not settings)."""
        if not self.setting:
            return None
        section, _, name = self.setting.partition(".")
        if not name:
            return getattr(CalibrationConfig(), section)
        return getattr(SECTIONS[section](), name)

    def _type(self) -> tuple[str, bool]:
        """(base type, None allowed) of the setting, as :mod:`nbcalib.config` reads it."""
        if not self.setting:
            return "str", False
        section, _, name = self.setting.partition(".")
        if not name:
            return "int", False
        return _kind(str(SECTIONS[section].__dataclass_fields__[name].type))

    def kind(self) -> str:
        """The setting's base type: ``int``, ``float``, ``str`` or ``bool``."""
        return self._type()[0]

    def optional(self) -> bool:
        """The setting may be None (``--points-per-pixel none``)."""
        return self._type()[1]


def _number(kind: str, optional: bool = False):
    def parse(text: str):
        if optional and text.lower() == "none":
            return None
        try:
            return int(text) if kind == "int" else float(text)
        except ValueError:
            what = "an integer" if kind == "int" else "a number"
            what += " or none" if optional else ""
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None

    return parse


#: Inputs and camera (``preprocess`` and ``run``): not settings, recorded as the job's inputs.
INPUT_OPTIONS = (
    Option("--camera", "", "camera file (ROS camera_info YAML, OpenCV/nbcalib YAML, calib.json)",
           "FILE"),
    Option("--camera-model", "", "pinhole, plumb_bob, fisheye, ...", "M"),
    Option("--intrinsics", "", "fx,fy,cx,cy[,xi]", "A,B,..."),
    Option("--distortion", "", "distortion coefficients", "A,B,..."),
)  # fmt: skip

#: Several pairs from one recording (``preprocess`` and ``run``): not settings, recorded as the
#: job's inputs (:mod:`nbcalib.preprocess.recording`).
RECORDING_OPTIONS = (
    Option("--frames", "", "folder of frames, one pair each: subfolders of one point cloud + one "
           "image, or the KITTI raw layout (velodyne_points/data, image_02/data)", "DIR"),
    Option("--images", "", "several images for the point clouds, one pair each (image i with "
           "scan i, or placed by --image-times)", "FILE"),
    Option("--image-times", "", "times of --images (seconds, on the scans' clock), or a bag's "
           "header stamps to make pairs at: a,b,... or a file, one time per line", "T"),
    Option("--scan-times", "", "times at which the point clouds of --images begin (default: "
           "k / --frame-rate)", "T"),
    Option("--every", "", "a pair at every Nth image of the recording (frames, --images, bags)",
           "N"),
    Option("--pair-count", "", "N pairs, their images spread evenly over the recording (per bag)",
           "N"),
)  # fmt: skip

PREPROCESS = (
    Option("--dynamic", "preprocess.mode", "moving spinning LiDAR (CT-ICP)", value="dynamic"),
    Option("--static", "preprocess.mode", "LiDAR at rest (accumulate)", value="static"),
    Option("--points-topic", "preprocess.points_topic", "bag topic of the point clouds", "T"),
    Option("--image-topic", "preprocess.image_topic", "bag topic of the images", "T"),
    Option("--camera-info-topic", "preprocess.camera_info_topic", "bag topic of CameraInfo", "T"),
    Option("--intensity-channel", "preprocess.intensity_channel",
           "point field of the intensity ('auto': reflectivity > intensity)", "C"),
    Option("--voxel-size", "preprocess.voxel_size", "dense cloud voxel, metres", "M"),
    Option("--min-distance", "preprocess.min_distance", "drop nearer points, metres", "M"),
    Option("--frame-rate", "preprocess.frame_rate", "scans per second of files without times",
           "HZ"),
    Option("--max-scans", "preprocess.max_scans", "use at most N scans per pair", "N"),
    Option("--neighbors", "preprocess.neighbors",
           "scans per pair made per image: the K around its image, its own included", "K"),
    Option("--image-scan-fraction", "preprocess.image_scan_fraction",
           "time of an image without a time as a fraction of its own scan's sweep (0.5: KITTI, "
           "a camera triggered when the LiDAR faces forward)", "F"),
    Option("--no-equalize", "preprocess.equalize", "keep raw intensities and image", value=False),
    Option("--lidar-origin", "preprocess.lidar_origin",
           "where the LiDAR sits in its clouds' frame, metres ('auto': found from a spinning "
           "scan's rings when the clouds are in a vehicle frame; 'cloud': their origin), for "
           "rendering and matching", "X,Y,Z"),
)  # fmt: skip

MATCHING = (
    Option("--matcher", "matching.matcher", "matcher ('auto': the best exported, else sift)"),
    Option("--match-threshold", "matching.match_threshold",
           "minimum match probability of a learned matcher (reference 0.01, paper 0.05)", "P"),
    Option("--rotate-camera", "matching.rotate_camera",
           "rotate the camera image clockwise before matching (0, 90, 180, 270)", "DEG"),
    Option("--rotate-lidar", "matching.rotate_lidar",
           "rotate the LiDAR image clockwise before matching (0, 90, 180, 270)", "DEG"),
    Option("--camera-normalization", "matching.camera_normalization",
           "normalisation of the camera image"),
    Option("--lidar-normalization", "matching.lidar_normalization",
           "normalisation of the LiDAR image"),
    Option("--camera-scale", "matching.camera_scale",
           "resample the camera image by S before matching the stored LiDAR image (default: the "
           "ratio of the two images' pixels per degree)", "S"),
    Option("--views", "matching.views",
           "camera-shaped LiDAR views at N headings around the LiDAR (0: match the stored "
           "LiDAR image instead, as the reference)", "N"),
    Option("--screen-views", "matching.screen_views",
           "run the learned matcher on the N views a cheap screen (descriptors' mutual nearest "
           "neighbours) ranks first, and on the views agreeing with the first (0: on every "
           "view)", "N"),
    Option("--matched-views", "matching.matched_views",
           "at most N screened views go to the learned matcher, the screen's best (0: no "
           "limit)", "N"),
    Option("--guess-pairs", "matching.guess_pairs",
           "several pairs: match them in turn until their pooled pose stops moving and N of "
           "them agree with it; the rest are not matched (0: match every pair)", "N"),
    Option("--search-radius", "matching.search_radius",
           "LiDAR keypoints on empty pixels take the nearest LiDAR point within this radius, "
           "pixels", "PX"),
    Option("--no-retries", "matching.retry_pixels_per_degree",
           "match each pair once, even when its guess fails (no finer inpainted views)",
           value=()),
    Option("--no-picture", "matching.draw", "do not write <name>_matches.png", value=False),
)  # fmt: skip

INITIAL_GUESS = (
    Option("--ransac-iterations", "initial_guess.ransac_iterations", "RANSAC hypotheses", "N"),
    Option("--ransac-threshold", "initial_guess.ransac_threshold",
           "inlier threshold on the reprojection error, pixels", "PX"),
    Option("--robust-kernel-width", "initial_guess.robust_kernel_width",
           "Cauchy kernel width of the LM refinement, pixels", "PX"),
    Option("--seed", "seed", "seed of every random choice (RANSAC)", "S"),
    Option("--min-inliers", "initial_guess.min_inliers",
           "inliers needed to accept an automatic guess (manual picks: --min-manual-inliers)",
           "N"),
    Option("--min-manual-inliers", "initial_guess.min_manual_inliers",
           "inliers needed to accept a guess from manual picks", "N"),
    Option("--precision-scale", "initial_guess.precision_scale",
           "accept an automatic guess only if K times its inliers' 95 %% noise bounds lie "
           "within 1 deg / 0.5 m (for the matches' shared error; 0: no such test)",
           "K"),
    Option("--no-confidence-weights", "initial_guess.confidence_weights",
           "weigh every match equally in the LM cost (paper Eq. 1, the reference) instead of "
           "by the matcher's confidence", value=False),
)  # fmt: skip

REFINE = (
    Option("--optimizer", "refine.optimizer",
           "hybrid: Nelder-Mead over the pyramid, then L-BFGS; or either alone"),
    Option("--cost", "refine.cost",
           "the intensity cost: regional (one joint histogram per image region of about "
           "--region-points points) or nid (one per pair, the paper's)"),
    Option("--region-points", "refine.region_points",
           "points of a region of the regional cost (each gets this many to twice this many)",
           "N"),
    Option("--bins", "refine.bins", "NID histogram bins", "N"),
    Option("--structure-weight", "refine.structure_weight",
           "weight of the depth-edge / image-edge NID beside the intensity NID (0: off)", "W"),
    Option("--points-per-pixel", "refine.points_per_pixel",
           "points per camera pixel the NID uses at most, a fixed random subset of the "
           "visible points (none: all)", "P"),
    Option("--job-points", "refine.job_points",
           "points of all pairs together at most, an equal share each (none: no joint "
           "limit)", "N"),
    Option("--cloud-memory", "refine.cloud_memory_mb",
           "megabytes kept of the dense clouds and what is computed from them between uses; "
           "the rest is read again from WORKDIR (same result, more time; none: no limit)",
           "MB"),
    Option("--max-outer", "refine.max_outer",
           "outer iterations at most, per pyramid level and per optimiser of the hybrid", "N"),
    Option("--depth-margin", "refine.depth_margin", "visibility depth margin, metres", "M"),
    Option("--window", "refine.window", "visibility window half-size, pixels", "PX"),
    Option("--no-hidden-point-removal", "refine.hidden_point_removal",
           "use every point in the image", value=False),
    Option("--pairs", "refine.max_pairs", "use only the first N pairs", "N"),
    Option("--pyramid-levels", "refine.pyramid_levels",
           "coarse image levels before the full resolution (0: full resolution only)", "N"),
    Option("--trust-translation", "refine.trust_translation",
           "trust region of the whole run: the camera centre stays within M metres of the "
           "start's", "M"),
    Option("--trust-rotation", "refine.trust_rotation_deg",
           "trust region of the whole run: the rotation stays within DEG degrees of the "
           "start's", "DEG"),
    Option("--refine-intrinsics", "refine.intrinsics",
           "refine the camera's focal length (focal), or focal length and principal point "
           "(focal,center), with the extrinsic over every pair; needs 3 pairs or more at "
           "several depths, and keeps the given camera when the frames cannot fix them "
           "(the report says which)", "WHAT"),
)  # fmt: skip

ASSESS = (
    Option("--confidence", "assess.confidence", "confidence of the stated intervals", "P"),
    Option("--restarts", "assess.restarts",
           "for a single pair, run fine registration again from N starts 1 deg / 5 cm around "
           "the result: their spread joins the uncertainty, and ends far from the result make "
           "it suspect (0: none, faster, but a real single shot's uncertainty is then "
           "understated; several pairs: none, their own spread counts)", "N"),
)  # fmt: skip

#: Every option that sets a setting, by flag.
SETTING_OPTIONS = {o.flag: o for o in (*PREPROCESS, *MATCHING, *INITIAL_GUESS, *REFINE, *ASSESS)}


#: Help of ``--init-uncertainty`` (``calibrate`` and ``run``).
INIT_UNCERTAINTY_HELP = (
    "how far --init may be from the truth (metres of camera centre, degrees), at the report's "
    "confidence; the verdict calls a result suspect that moved farther from the start than "
    "this and its own uncertainty allow (default: the trust region, --trust-translation / "
    "--trust-rotation)"
)


#: Options of ``run`` itself (not settings): how the job runs and where it starts.
RUN_OPTIONS = (
    Option("--config", "", "settings from a TOML or YAML file", "FILE"),
    Option("--force", "", "recompute every stage, even a finished result", value=True),
    Option("--from", "", "recompute from STAGE on", "STAGE"),
    Option("--until", "", "stop after STAGE (e.g. --until initial-guess to check the guess)",
           "STAGE"),
    Option("--no-matching", "",
           "skip find-matches and the automatic guess: start from --init (or --manual)",
           value=True),
    Option("--no-report", "", "skip the report", value=True),
    Option("--init", "", "T_lidar_camera x,y,z,qx,qy,qz,qw: the start when the automatic guess "
           "fails (with --no-matching: the start)", "X,Y,Z,QX,QY,QZ,QW"),
    Option("--init-uncertainty", "", INIT_UNCERTAINTY_HELP, ("M", "DEG")),
    Option("--manual", "", "hand-picked correspondences (nbcalib initial-guess --help)", "FILE"),
    Option("--prior", "", "rough T_lidar_camera that matching renders its views around",
           "X,Y,Z,QX,QY,QZ,QW"),
    Option("--model-dir", "", "exported models (default: $NBCALIB_MODEL_DIR or the user cache)",
           "DIR"),
    Option("--camera-topics", "", "several cameras: their image topics, comma-separated "
           "(default: every image topic of a bag that has several)", "T1,T2,..."),
    Option("--rig", "", "several cameras with known camera-to-camera extrinsics (a Kalibr "
           "camchain or an nbcalib rig file): one rig pose from every camera", "FILE"),
    Option("--camera-image", "", "several cameras from files: a camera's name, its image and "
           "its camera file, once per camera, with the point clouds as INPUT or --points",
           ("NAME", "IMAGE", "CAMERA")),
)  # fmt: skip


def _choices(option: Option):
    if option.choices is not None:
        return option.choices
    from nbcalib.matching.config import MATCHER_CHOICES, NORMALIZATIONS, ROTATIONS
    from nbcalib.registration.config import COSTS, INTRINSICS_MODES, OPTIMIZERS

    known = {
        "matching.matcher": MATCHER_CHOICES,
        "matching.camera_normalization": NORMALIZATIONS,
        "matching.lidar_normalization": NORMALIZATIONS,
        "matching.rotate_camera": ROTATIONS,
        "matching.rotate_lidar": ROTATIONS,
        "refine.optimizer": OPTIMIZERS,
        "refine.cost": tuple(COSTS),
        "refine.intrinsics": tuple(INTRINSICS_MODES),
    }
    return known.get(option.setting)


def add_options(group, options) -> None:
    """Add options to a parser or argument group, defaults left out of the namespace.

    The help shows each setting's default, from its dataclass.
    """
    exclusive = {}
    for option in options:
        default = option.default()
        help_text = option.help
        if option.takes_value and default is not None and default != "":
            help_text = f"{help_text} (default: {default})"
        kwargs: dict[str, Any] = {"default": argparse.SUPPRESS, "help": help_text}
        if option.takes_value:
            kind = option.kind()
            if kind in ("int", "float"):
                kwargs["type"] = _number(kind, option.optional())
            kwargs["metavar"] = option.metavar
            choices = _choices(option)
            if choices is not None:
                kwargs["choices"] = choices
        else:
            kwargs["action"] = "store_const"
            kwargs["const"] = option.value
        target = group
        if option.setting == "preprocess.mode":  # --dynamic / --static exclude each other
            if "mode" not in exclusive:
                exclusive["mode"] = group.add_mutually_exclusive_group()
            target = exclusive["mode"]
        dest = "mode" if option.setting == "preprocess.mode" else option.dest
        target.add_argument(option.flag, dest=dest, **kwargs)


def given_settings(args: argparse.Namespace) -> dict[str, Any]:
    """``{"section.field": value}`` of the setting options given on the command line."""
    values = {}
    given = vars(args)
    for option in SETTING_OPTIONS.values():
        dest = "mode" if option.setting == "preprocess.mode" else option.dest
        if dest in given:
            values[option.setting] = given[dest]
    return values


def file_settings(data: dict, path) -> tuple[dict, dict]:
    """Split a config file (:func:`nbcalib.config.read_config_file`) into settings and the rest.

    Keys are field names in a section's table (``[refine] bins = 8``) or option names anywhere
    (``bins = 8``, ``[calibrate] optimizer = "lbfgs"``, ``dynamic = true``).

    Returns
    -------
    settings : dict
        ``{"section.field": value}``.
    other : dict
        Options that are not settings (``camera``, ``init``, ``no-report``, ``inputs`` ...), by
        their namespace name (``no_report``), for the command to use.

    Raises
    ------
    InputError
        An unknown table or key, or a switch whose value is not true or false; names ``path``.
    """
    stage_tables = ("run", "preprocess", "find-matches", "initial-guess", "calibrate", "report")
    others = {o.flag: o for o in (*INPUT_OPTIONS, *RECORDING_OPTIONS, *RUN_OPTIONS)}
    settings: dict[str, Any] = {}
    other: dict[str, Any] = {}
    entries = []
    for key, value in data.items():
        if isinstance(value, dict) and key != "inputs":
            if key not in SECTIONS and key not in stage_tables:
                tables = ", ".join(sorted({*SECTIONS, *stage_tables}))
                raise InputError(f"unknown table [{key}]: tables may be {tables}", path)
            entries += [(key, k, v) for k, v in value.items()]
        else:
            entries.append((None, key, value))
    renamed = renamed_settings()
    for table, key, value in entries:
        name = str(key).lstrip("-").replace("-", "_")
        if f"{table}.{name}" in renamed:
            new = renamed[f"{table}.{name}"]
            log.warning("%s: %s.%s is now called %s", path, table, name, new)
            name = new.partition(".")[2]
        if table in SECTIONS and name in {f.name for f in fields(SECTIONS[table])}:
            if isinstance(value, dict):  # a nested table: [preprocess.odometry]
                from nbcalib.config import flatten

                nested: dict[str, Any] = {}
                flatten(f"{table}.{name}", value, nested)
                for setting, item in nested.items():
                    _put(settings, setting, item, path)
            else:
                _put(settings, f"{table}.{name}", value, path)
            continue
        if table is None and name in ("seed", "inputs"):
            (settings if name == "seed" else other)[name] = value
            continue
        flag = "--" + name.replace("_", "-")
        option = SETTING_OPTIONS.get(flag) or others.get(flag)
        if option is None:
            raise InputError(f"unknown option {flag} (see nbcalib run --help)", path)
        if not option.takes_value:
            if not isinstance(value, bool):
                raise InputError(f"{flag} must be true or false, got {value!r}", path)
            if not value:
                continue
            value = option.value
        if option.setting:
            _put(settings, option.setting, value, path)
        else:
            other[option.dest] = value
    return settings, other


def _put(settings: dict, setting: str, value, path) -> None:
    if setting in settings and settings[setting] != value:
        raise InputError(f"{setting} is given twice, with different values", path)
    settings[setting] = value


def build_config(
    args: argparse.Namespace,
    *,
    base: CalibrationConfig | None = None,
    file_values: dict | None = None,
    file_path=None,
) -> CalibrationConfig:
    """The command line over a config file's settings over ``base`` (default: the defaults).

    Raises
    ------
    InputError
        A setting out of range (the message names the option or the file).
    """
    from nbcalib.wording import spelling

    config = base or CalibrationConfig()
    if file_values:
        try:
            config = set_values(config, file_values)
        except ValueError as exc:
            with spelling(None):  # the file's own names for its settings (``refine.bins``)
                raise InputError(str(exc), file_path) from None
    given = given_settings(args)
    try:
        return set_values(config, given)
    except ValueError as exc:
        flags = [o.flag for o in SETTING_OPTIONS.values() if o.setting in given]
        with spelling(None):  # the setting's name, then the options that set it
            raise InputError(f"{exc} (options: {' '.join(sorted(set(flags)))})") from None


#: Inputs the command line takes by argparse alone (not in an Option table).
_OTHER_INPUT_FLAGS = {"inputs.points": "--points", "inputs.image": "--image"}


def flag_names() -> dict[str, str]:
    """The API name of everything the command line sets -> its flag (:mod:`nbcalib.wording`).

    Settings ``section.field`` (and ``seed``) from the stages' Option tables, inputs
    ``inputs.field`` from the input tables, and ``run.name`` from :data:`RUN_OPTIONS`: one
    table, so that a message below the command line names a setting as the API does and the
    command line's user reads the flag.
    """
    names = dict(_OTHER_INPUT_FLAGS)
    for option in (*PREPROCESS, *MATCHING, *INITIAL_GUESS, *REFINE, *ASSESS):
        if "." in option.setting and option.takes_value:  # a switch sets one value, not any
            names.setdefault(option.setting, option.flag)
    for option in (*INPUT_OPTIONS, *RECORDING_OPTIONS):
        names[f"inputs.{option.dest}"] = option.flag
    for option in RUN_OPTIONS:
        names[f"run.{option.dest}"] = option.flag
    return names


def flag_spelling():
    """The command line's spelling of messages: API names as flags (:func:`flag_names`)."""
    from nbcalib.wording import translator

    return translator(flag_names())
