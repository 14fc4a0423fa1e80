"""Data manifests: the public datasets people calibrate with, and checks of a downloaded copy.

A manifest is one YAML file per dataset (``data_manifests/<name>.yaml`` in the source tree,
``nbcalib/data_manifests/`` in an installed wheel) that says where to download the data, its
licence, size, sensors, bag topics, camera model and intrinsics, the published reference
extrinsic where one exists, the files with their sizes and SHA-256 hashes where known, and the
``nbcalib run`` command for it. Every fact has a source URL; unknown values are ``null``.

Schema 1 (every key required unless marked optional)::

    schema: 1
    name: str                    # [a-z0-9_]+, equal to the file name without .yaml
    title: str
    description: str
    homepage: url
    downloads: [url, ...]
    licence: {name: str | null, url: url | null, note: str (optional)}
    size: {bytes: int | null, text: str}
    sensors:
      lidar: {kind: spinning | non_repetitive | map, model: str | null, note: str (optional)}
      camera: {model: str | null, note: str (optional)}
    topics: {points: str | null, image: str | null, camera_info: str | null} | null
    camera: {camera_model, width: int | null, height: int | null, intrinsics: [...],
             distortion_coeffs: [...], source: str} | null      # calib.json layouts
    reference_extrinsic: {T_lidar_camera: [x, y, z, qx, qy, qz, qw], source: str,
                          note: str (optional)} | null
    files:                       # relative to the dataset directory DIR
      - {path: str, url: url (optional), bytes: int | null, sha256: 64 hex | null,
         extracts_to: str (optional), optional: bool (optional)}
    run: str                     # "nbcalib run ..." with {dir} and {workdir} placeholders
    sources: [url, ...]
    notes: str (optional)

``T_lidar_camera`` follows calib.json: ``p_lidar = T_lidar_camera @ p_camera``, metres,
quaternion xyzw, camera optical frame (docs/conventions.md). A file with ``extracts_to`` counts as
present when it is absent but that path (inside DIR) exists, i.e. the archive was unpacked and
removed. A file marked ``optional`` may be absent.

Nothing here downloads: :func:`verify_dataset` only reads files the user already has.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import shlex
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nbcalib.errors import InputError
from nbcalib.progress import Progress

#: Version of the manifest layout this module reads.
SCHEMA_VERSION = 1
#: LiDAR kinds a manifest may name.
LIDAR_KINDS = ("spinning", "non_repetitive", "map")
#: Bytes read per step when hashing.
HASH_CHUNK = 1 << 20

#: Progress callback of :func:`verify_dataset`: ``(done_bytes, total_bytes, file_name)``.
ProgressCallback = Callable[[int, int, str], None]

_NAME = re.compile(r"^[a-z0-9_]+$")
_SHA256 = re.compile(r"^[0-9a-f]{64}$")
_URL = re.compile(r"^https?://\S+$")

# Parameter counts of the calib.json layouts (docs/conventions.md section 7); kept here so that
# validating a manifest does not import the numba camera kernels.
_CAMERA_COUNTS = {
    "pinhole": (4, 0),
    "plumb_bob": (4, 5),
    "rational_polynomial": (4, 8),
    "fisheye": (4, 4),
    "equidistant": (4, 4),
    "atan": (4, 1),
    "omnidir": (5, 4),
    "equirectangular": (2, 0),
}

_TOP_KEYS = {
    "schema": True,
    "name": True,
    "title": True,
    "description": True,
    "homepage": True,
    "downloads": True,
    "licence": True,
    "size": True,
    "sensors": True,
    "topics": True,
    "camera": True,
    "reference_extrinsic": True,
    "files": True,
    "run": True,
    "sources": True,
    "notes": False,
}


@dataclass(frozen=True)
class ManifestFile:
    """One file of a dataset, relative to the dataset directory.

    Attributes
    ----------
    path : str
        Relative path inside the dataset directory (``/`` separated).
    url : str or None
        Where to download it.
    bytes : int or None
        Size in bytes, or None when unknown.
    sha256 : str or None
        Lower-case hex SHA-256, or None when unknown.
    extracts_to : str or None
        A path inside the dataset directory that exists once the archive is unpacked.
    optional : bool
        Whether the file may be absent.
    """

    path: str
    url: str | None = None
    bytes: int | None = None
    sha256: str | None = None
    extracts_to: str | None = None
    optional: bool = False


@dataclass(frozen=True)
class Manifest:
    """A validated data manifest; ``data`` holds the whole parsed file.

    Attributes
    ----------
    name : str
        Dataset name (the file name without ``.yaml``).
    path : Path
        The manifest file.
    data : dict
        The parsed YAML, validated against schema 1 (module docstring).
    files : tuple of ManifestFile
    """

    name: str
    path: Path
    data: dict = field(repr=False)
    files: tuple[ManifestFile, ...] = ()

    @property
    def title(self) -> str:
        """One-line title."""
        return self.data["title"]

    @property
    def licence(self) -> str:
        """Licence name, or ``"unknown"``."""
        return self.data["licence"]["name"] or "unknown"

    @property
    def size_text(self) -> str:
        """Total size for people: bytes in GB/MB when known, else the manifest's text."""
        size = self.data["size"]
        if size["bytes"] is not None:
            return format_bytes(size["bytes"])
        return size["text"]

    @property
    def sensors_text(self) -> str:
        """``"<lidar kind> <model or LiDAR> + camera"``, for tables."""
        lidar = self.data["sensors"]["lidar"]
        model = lidar["model"] or "LiDAR"
        camera = self.data["camera"]
        camera_model = f" ({camera['camera_model']})" if camera else ""
        return f"{lidar['kind']} {model} + camera{camera_model}"

    def run_command(self, directory: str | os.PathLike, workdir: str | os.PathLike) -> str:
        """The ``nbcalib run`` command for the dataset in ``directory``, shell-quoted.

        Parameters
        ----------
        directory : str or PathLike
            Where the dataset was downloaded (and unpacked); replaces ``{dir}``.
        workdir : str or PathLike
            The work directory to create; replaces ``{workdir}``.
        """
        text = " ".join(self.data["run"].split())
        return text.replace("{dir}", shlex.quote(os.fspath(directory))).replace(
            "{workdir}", shlex.quote(os.fspath(workdir))
        )


# ---------------------------------------------------------------------- finding manifests
def manifest_dir() -> Path:
    """The folder of the manifests shipped with nbcalib.

    An installed wheel carries them in ``nbcalib/data_manifests/``; a source checkout (or an
    editable install) has them in ``data_manifests/`` next to the package.
    """
    package = Path(__file__).resolve().parent
    for candidate in (package / "data_manifests", package.parent / "data_manifests"):
        if candidate.is_dir():
            return candidate
    raise InputError(
        "the data manifests are not installed (expected nbcalib/data_manifests in the package "
        "or data_manifests/ in the source tree)",
        package,
    )


def manifest_paths(directory: str | os.PathLike | None = None) -> list[Path]:
    """Manifest files (``*.yaml``) in ``directory`` (default :func:`manifest_dir`), sorted."""
    folder = manifest_dir() if directory is None else Path(directory)
    if not folder.is_dir():
        raise InputError("manifest folder not found", folder)
    return sorted(folder.glob("*.yaml"))


def list_manifests(directory: str | os.PathLike | None = None) -> list[Manifest]:
    """Load and validate every manifest of ``directory`` (default: the shipped ones)."""
    return [load_manifest(path) for path in manifest_paths(directory)]


def find_manifest(name_or_path: str, directory: str | os.PathLike | None = None) -> Manifest:
    """Load a manifest by dataset name, or from a ``.yaml`` file path.

    Parameters
    ----------
    name_or_path : str
        A dataset name (``kitti_raw_2011_09_26``) or the path of a manifest file.
    directory : str or PathLike, optional
        Where to look names up (default :func:`manifest_dir`).
    """
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.is_file():
        return load_manifest(candidate)
    paths = {path.stem: path for path in manifest_paths(directory)}
    if name_or_path not in paths:
        known = ", ".join(sorted(paths)) or "none"
        raise InputError(f"no dataset named '{name_or_path}' (known: {known})")
    return load_manifest(paths[name_or_path])


def load_manifest(path: str | os.PathLike) -> Manifest:
    """Read and validate one manifest file; :class:`InputError` names the file and the key."""
    import yaml

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("manifest not found", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read manifest: {exc}", path) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise InputError(f"invalid YAML{where}", path) from None
    validate_manifest(data, path=path)
    files = tuple(ManifestFile(**entry) for entry in data["files"])
    return Manifest(name=data["name"], path=path, data=data, files=files)


# ---------------------------------------------------------------------- schema check
def validate_manifest(data: Any, *, path: str | os.PathLike | None = None) -> None:
    """Check a parsed manifest against schema 1 (module docstring).

    Raises
    ------
    InputError
        The first problem found, naming the key (``camera.intrinsics``) and the file.
    """
    check = _Checker(path)
    check.mapping(data, "manifest", _TOP_KEYS)
    if data["schema"] != SCHEMA_VERSION:
        check.fail("schema", f"must be {SCHEMA_VERSION}, got {data['schema']!r}")
    check.string(data["name"], "name")
    if not _NAME.match(data["name"]):
        check.fail("name", "must be lower-case letters, digits and underscores")
    if path is not None and Path(path).stem != data["name"]:
        check.fail("name", f"'{data['name']}' differs from the file name '{Path(path).stem}'")
    for key in ("title", "description", "run"):
        check.string(data[key], key)
    check.url(data["homepage"], "homepage")
    check.urls(data["downloads"], "downloads")
    check.urls(data["sources"], "sources")
    if data.get("notes") is not None:
        check.string(data["notes"], "notes")
    _check_licence(check, data["licence"])
    _check_size(check, data["size"])
    _check_sensors(check, data["sensors"])
    _check_topics(check, data["topics"])
    _check_camera(check, data["camera"])
    _check_extrinsic(check, data["reference_extrinsic"])
    _check_files(check, data["files"])
    run = " ".join(data["run"].split())
    if not run.startswith("nbcalib run ") or "{workdir}" not in run or "{dir}" not in run:
        check.fail("run", "must start with 'nbcalib run ' and use {dir} and {workdir}")


class _Checker:
    """Small type checks that raise one-line InputErrors naming the manifest key."""

    def __init__(self, path):
        self.path = path

    def fail(self, key: str, problem: str):
        raise InputError(f"{key}: {problem}", self.path)

    def mapping(self, value, key: str, keys: dict[str, bool]) -> None:
        if not isinstance(value, dict):
            self.fail(key, f"must be a mapping, got {type(value).__name__}")
        missing = [k for k, required in keys.items() if required and k not in value]
        if missing:
            self.fail(key, f"missing {', '.join(missing)}")
        unknown = sorted(set(value) - set(keys))
        if unknown:
            self.fail(key, f"unknown key(s) {', '.join(map(str, unknown))}")

    def string(self, value, key: str, *, nullable: bool = False) -> None:
        if value is None and nullable:
            return
        if not isinstance(value, str) or not value.strip():
            self.fail(key, "must be a non-empty string" + (" or null" if nullable else ""))

    def url(self, value, key: str, *, nullable: bool = False) -> None:
        self.string(value, key, nullable=nullable)
        if value is not None and not _URL.match(value):
            self.fail(key, f"not an http(s) URL: {value!r}")

    def urls(self, value, key: str) -> None:
        if not isinstance(value, list) or not value:
            self.fail(key, "must be a non-empty list of URLs")
        for i, item in enumerate(value):
            self.url(item, f"{key}[{i}]")

    def count(self, value, key: str) -> None:
        if value is None:
            return
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            self.fail(key, "must be a whole number >= 0 or null")

    def numbers(self, value, key: str, count: int | None = None) -> None:
        ok = isinstance(value, list) and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
            for x in value
        )
        if not ok:
            self.fail(key, "must be a list of finite numbers")
        if count is not None and len(value) != count:
            self.fail(key, f"must have {count} numbers, got {len(value)}")

    def relative_path(self, value, key: str) -> None:
        self.string(value, key)
        parts = Path(value).parts
        if Path(value).is_absolute() or ".." in parts or "\\" in value:
            self.fail(key, f"must be a relative path inside the dataset directory: {value!r}")


def _check_licence(check: _Checker, licence) -> None:
    check.mapping(licence, "licence", {"name": True, "url": True, "note": False})
    check.string(licence["name"], "licence.name", nullable=True)
    check.url(licence["url"], "licence.url", nullable=True)
    if licence["name"] is None and not licence.get("note"):
        check.fail("licence.note", "say where to look when the licence name is unknown")


def _check_size(check: _Checker, size) -> None:
    check.mapping(size, "size", {"bytes": True, "text": True})
    check.count(size["bytes"], "size.bytes")
    check.string(size["text"], "size.text")


def _check_sensors(check: _Checker, sensors) -> None:
    check.mapping(sensors, "sensors", {"lidar": True, "camera": True})
    lidar, camera = sensors["lidar"], sensors["camera"]
    check.mapping(lidar, "sensors.lidar", {"kind": True, "model": True, "note": False})
    if lidar["kind"] not in LIDAR_KINDS:
        check.fail("sensors.lidar.kind", f"must be one of {', '.join(LIDAR_KINDS)}")
    check.string(lidar["model"], "sensors.lidar.model", nullable=True)
    check.mapping(camera, "sensors.camera", {"model": True, "note": False})
    check.string(camera["model"], "sensors.camera.model", nullable=True)


def _check_topics(check: _Checker, topics) -> None:
    if topics is None:
        return
    check.mapping(topics, "topics", {"points": True, "image": True, "camera_info": True})
    for key, topic in topics.items():
        check.string(topic, f"topics.{key}", nullable=True)
        if topic is not None and not topic.startswith("/"):
            check.fail(f"topics.{key}", f"a ROS topic starts with '/': {topic!r}")


def _check_camera(check: _Checker, camera) -> None:
    if camera is None:
        return
    keys = dict.fromkeys(
        ("camera_model", "width", "height", "intrinsics", "distortion_coeffs", "source"), True
    )
    check.mapping(camera, "camera", keys)
    model = camera["camera_model"]
    if model not in _CAMERA_COUNTS:
        check.fail("camera.camera_model", f"must be one of {', '.join(_CAMERA_COUNTS)}")
    n_intrinsics, n_distortion = _CAMERA_COUNTS[model]
    check.numbers(camera["intrinsics"], "camera.intrinsics", n_intrinsics)
    check.numbers(camera["distortion_coeffs"], "camera.distortion_coeffs")
    if len(camera["distortion_coeffs"]) not in (0, n_distortion):
        check.fail(
            "camera.distortion_coeffs",
            f"{model} takes {n_distortion} coefficients, got {len(camera['distortion_coeffs'])}",
        )
    for key in ("width", "height"):
        check.count(camera[key], f"camera.{key}")
        if camera[key] == 0:
            check.fail(f"camera.{key}", "must be positive or null")
    if (camera["width"] is None) != (camera["height"] is None):
        check.fail("camera", "give both width and height, or neither")
    check.string(camera["source"], "camera.source")


def _check_extrinsic(check: _Checker, extrinsic) -> None:
    if extrinsic is None:
        return
    keys = {"T_lidar_camera": True, "source": True, "note": False}
    check.mapping(extrinsic, "reference_extrinsic", keys)
    values = extrinsic["T_lidar_camera"]
    check.numbers(values, "reference_extrinsic.T_lidar_camera", 7)
    norm = math.sqrt(sum(q * q for q in values[3:]))
    if abs(norm - 1.0) > 1e-6:
        check.fail(
            "reference_extrinsic.T_lidar_camera",
            f"quaternion [qx, qy, qz, qw] must have unit length, got {norm:.9f}",
        )
    check.string(extrinsic["source"], "reference_extrinsic.source")


def _check_files(check: _Checker, files) -> None:
    if not isinstance(files, list) or not files:
        check.fail("files", "must be a non-empty list")
    keys = {
        "path": True,
        "url": False,
        "bytes": True,
        "sha256": True,
        "extracts_to": False,
        "optional": False,
    }
    seen = set()
    for i, entry in enumerate(files):
        key = f"files[{i}]"
        check.mapping(entry, key, keys)
        check.relative_path(entry["path"], f"{key}.path")
        if entry["path"] in seen:
            check.fail(f"{key}.path", f"listed twice: {entry['path']}")
        seen.add(entry["path"])
        if "url" in entry:
            check.url(entry["url"], f"{key}.url", nullable=True)
        check.count(entry["bytes"], f"{key}.bytes")
        if entry["sha256"] is not None and not (
            isinstance(entry["sha256"], str) and _SHA256.match(entry["sha256"])
        ):
            check.fail(f"{key}.sha256", "must be 64 lower-case hex digits or null")
        if entry.get("extracts_to") is not None:
            check.relative_path(entry["extracts_to"], f"{key}.extracts_to")
        if not isinstance(entry.get("optional", False), bool):
            check.fail(f"{key}.optional", "must be true or false")


# ---------------------------------------------------------------------- verifying a copy
@dataclass(frozen=True)
class FileCheck:
    """The outcome for one manifest file.

    Attributes
    ----------
    file : ManifestFile
    status : str
        ``"ok"`` (present; size and hash match where known), ``"extracted"`` (absent, but its
        ``extracts_to`` path exists), ``"absent"`` (an optional file that is not there),
        ``"missing"``, ``"size_mismatch"`` or ``"hash_mismatch"``.
    detail : str
        What was checked or what differs, for people.
    """

    file: ManifestFile
    status: str
    detail: str

    @property
    def failed(self) -> bool:
        """Whether this file makes the copy unusable."""
        return self.status in ("missing", "size_mismatch", "hash_mismatch")


def verify_dataset(
    manifest: Manifest,
    directory: str | os.PathLike,
    *,
    hashes: bool = True,
    progress: bool | ProgressCallback | None = None,
) -> list[FileCheck]:
    """Check a downloaded copy of a dataset against its manifest; nothing is downloaded.

    Parameters
    ----------
    manifest : Manifest
    directory : str or PathLike
        The folder the files were downloaded (and unpacked) into.
    hashes : bool, keyword-only
        Compute SHA-256 of files whose hash the manifest knows (reads every byte).
    progress : bool or callable, keyword-only, optional
        While hashing: ``True`` for a progress display per file (:func:`sha256_file`), or
        ``progress(done_bytes, total_bytes, file_name)``.

    Returns
    -------
    list of FileCheck
        One per manifest file, in manifest order; see :attr:`FileCheck.failed`.

    Raises
    ------
    InputError
        ``directory`` does not exist or is not a folder.
    """
    root = Path(directory)
    if not root.is_dir():
        raise InputError("dataset directory not found", root)
    checks = []
    for entry in manifest.files:
        path = root / entry.path
        if not path.is_file():
            checks.append(_absent_check(root, entry))
            continue
        size = path.stat().st_size
        if entry.bytes is not None and size != entry.bytes:
            detail = f"{size} bytes, expected {entry.bytes}"
            checks.append(FileCheck(entry, "size_mismatch", detail))
            continue
        known = [f"{size} bytes" + (" (as expected)" if entry.bytes is not None else "")]
        if entry.sha256 is not None and hashes:
            digest = sha256_file(path, progress=progress)
            if digest != entry.sha256:
                detail = f"sha256 {digest}, expected {entry.sha256}"
                checks.append(FileCheck(entry, "hash_mismatch", detail))
                continue
            known.append("sha256 matches")
        elif entry.sha256 is None:
            known.append("no published hash")
        checks.append(FileCheck(entry, "ok", ", ".join(known)))
    return checks


def _absent_check(root: Path, entry: ManifestFile) -> FileCheck:
    if entry.extracts_to is not None and (root / entry.extracts_to).exists():
        return FileCheck(entry, "extracted", f"archive absent; {entry.extracts_to} exists")
    if entry.optional:
        return FileCheck(entry, "absent", "optional, not present")
    where = f" (nor its contents {entry.extracts_to})" if entry.extracts_to else ""
    return FileCheck(entry, "missing", f"not found{where}")


def sha256_file(path: str | os.PathLike, *, progress: bool | ProgressCallback | None = None) -> str:
    """Lower-case hex SHA-256 of a file, read in 1 MiB chunks.

    Parameters
    ----------
    path : str or PathLike
    progress : bool or callable, keyword-only, optional
        ``True`` for a progress display in bytes (:class:`nbcalib.progress.Progress`: a bar on a
        terminal, step lines in a log, nothing when the ``nbcalib`` logger is quiet), or
        ``progress(done_bytes, total_bytes, file_name)`` after every chunk.
    """
    path = Path(path)
    total = path.stat().st_size
    digest = hashlib.sha256()
    done = 0
    display = Progress(total, "sha256", enabled=progress is True, unit="B")
    with display, open(path, "rb") as stream:
        for chunk in _chunks(stream):
            digest.update(chunk)
            done += len(chunk)
            if callable(progress):
                progress(done, total, path.name)
            display.update(len(chunk), path.name)
    return digest.hexdigest()


def _chunks(stream) -> Iterator[bytes]:
    while chunk := stream.read(HASH_CHUNK):
        yield chunk


def format_bytes(count: int) -> str:
    """``1234567 -> "1.2 MB"`` (decimal units, as download pages use)."""
    value = float(count)
    for unit in ("B", "kB", "MB"):
        if value < 1000:
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1000
    return f"{value:.1f} GB"
