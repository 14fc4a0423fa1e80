"""One config tree for the whole pipeline: a frozen dataclass per stage, composed.

::

    CalibrationConfig
      preprocess     PreprocessConfig     (nbcalib.preprocess.config)    dense clouds, images
      matching       MatchConfig          (nbcalib.matching.config)      matcher, views
      initial_guess  InitialGuessConfig   (nbcalib.initial_guess.config) RANSAC, LM, success
      refine         RefineConfig         (nbcalib.registration.config)  NID registration
      assess         AssessConfig         (nbcalib.report.config)        uncertainty, verdict
      seed           int                  the random seed of every stage (RANSAC, sampling)

Each stage's defaults live in its dataclass and nowhere else: the command line
(:mod:`nbcalib.commands._options`), config files (this module) and :func:`nbcalib.calibrate`'s
keywords all map onto these fields. None of these modules imports numba, so building a config is
cheap.

**Config files** are TOML or YAML with one table per section, keys = field names::

    # job.toml
    seed = 3
    [preprocess]
    voxel_size = 0.01
    [matching]
    matcher = "sift"
    [refine]
    optimizer = "nelder_mead"

The command line also accepts its own long option names as keys (``voxel-size = 0.01``, at the
top or in any table: see ``nbcalib run --help``). The config a job used is written into its
work directory as ``nbcalib_config.yaml`` (:func:`write_config`), which ``--config`` reads back.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from nbcalib.errors import InputError
from nbcalib.initial_guess.config import InitialGuessConfig
from nbcalib.matching.config import MatchConfig
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.registration.config import RefineConfig
from nbcalib.report.config import AssessConfig

__all__ = [
    "SECTIONS",
    "CalibrationConfig",
    "config_from_dict",
    "config_from_record",
    "config_to_dict",
    "flatten",
    "read_config_file",
    "renamed_settings",
    "set_values",
    "write_config",
]


@dataclass(frozen=True)
class CalibrationConfig:
    """Every setting of a calibration job (module docstring).

    Attributes
    ----------
    preprocess : PreprocessConfig
    matching : MatchConfig
    initial_guess : InitialGuessConfig
    refine : RefineConfig
    assess : AssessConfig
    seed : int
        Seed of every random choice (RANSAC of matching and of the initial guess): the same
        seed gives the same result.
    """

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    matching: MatchConfig = field(default_factory=MatchConfig)
    initial_guess: InitialGuessConfig = field(default_factory=InitialGuessConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    assess: AssessConfig = field(default_factory=AssessConfig)
    seed: int = 0

    def __post_init__(self):
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ValueError(f"seed must be an integer, got {self.seed!r}")
        if not 0 <= self.seed < 2**63:
            raise ValueError(f"seed must be in [0, 2**63), got {self.seed}")


#: The sections of :class:`CalibrationConfig`: name -> dataclass.
SECTIONS: dict[str, type] = {
    "preprocess": PreprocessConfig,
    "matching": MatchConfig,
    "initial_guess": InitialGuessConfig,
    "refine": RefineConfig,
    "assess": AssessConfig,
}

_TOP_LEVEL = ("seed",)


def renamed_settings() -> dict[str, str]:
    """``section.field`` of settings under a former name -> their ``section.field`` now."""
    from nbcalib.registration.config import RENAMED as REFINE_RENAMED

    return {f"refine.{old}": f"refine.{new}" for old, new in REFINE_RENAMED.items()}


def _kind(annotation: str) -> tuple[str, bool]:
    """(base type, None allowed) of a field annotation such as ``"int | None"``."""
    parts = [p.strip() for p in annotation.split("|")]
    optional = "None" in parts
    base = next((p for p in parts if p != "None"), "None")
    return base, optional


def _coerce(where: str, annotation: str, value: Any) -> Any:
    """``value`` as the field's type, or a ValueError naming ``where``."""
    base, optional = _kind(annotation)
    if isinstance(value, str) and value.lower() == "none" and optional and base != "str":
        value = None  # TOML has no null: "none" empties an optional number
    if value is None:
        if optional:
            return None
        raise ValueError(f"{where} must not be empty")
    if base == "bool":
        if isinstance(value, bool):
            return value
        raise ValueError(f"{where} must be true or false, got {value!r}")
    if base == "int":
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ValueError(f"{where} must be an integer, got {value!r}")
    if base == "float":
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ValueError(f"{where} must be a number, got {value!r}")
    if base == "str":
        if isinstance(value, str):
            return value
        raise ValueError(f"{where} must be a string, got {value!r}")
    if base.startswith("tuple"):
        if isinstance(value, (list, tuple)) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
        ):
            return tuple(float(v) for v in value)
        raise ValueError(f"{where} must be a list of numbers, got {value!r}")
    return value  # pragma: no cover - every field has one of the types above


def _field_type(cls: type, name: str) -> str:
    return str(cls.__dataclass_fields__[name].type)


def _replaced(obj, path: list[str], value: Any, where: str):
    """``obj`` (a dataclass) with the setting at ``path`` (nested names) set to ``value``."""
    cls = type(obj)
    name = path[0]
    if name not in cls.__dataclass_fields__:
        raise ValueError(f"unknown setting {where!r}")
    if len(path) == 1:
        if dataclasses.is_dataclass(getattr(obj, name)):
            raise ValueError(f"{where} is a table of settings, not a value")
        return replace(obj, **{name: _coerce(where, _field_type(cls, name), value)})
    inner = getattr(obj, name)
    if not dataclasses.is_dataclass(inner):
        raise ValueError(f"unknown setting {where!r}")
    return replace(obj, **{name: _replaced(inner, path[1:], value, where)})


def set_values(config: CalibrationConfig, values: dict[str, Any]) -> CalibrationConfig:
    """A copy of ``config`` with ``{"section.field": value, "seed": value}`` changed.

    Nested settings are dotted further (``preprocess.odometry.knn``). Values are checked
    against the field types and each section's own checks. Former names of renamed settings
    (:func:`renamed_settings`: ``refine.max_total_translation``) set the setting's new name.

    Raises
    ------
    ValueError
        An unknown key, a value of the wrong type, or a value the section refuses.
    """
    top: dict[str, Any] = {}
    sections = {name: getattr(config, name) for name in SECTIONS}
    renamed = renamed_settings()
    for key, value in values.items():
        if key in renamed:
            if renamed[key] in values and values[renamed[key]] != value:
                raise ValueError(
                    f"{key} (the former name of {renamed[key]}) and {renamed[key]} are both "
                    "given, with different values"
                )
            key = renamed[key]
        section, _, rest = key.partition(".")
        if not rest and section in _TOP_LEVEL:
            top[section] = _coerce(section, "int", value)
            continue
        if section not in SECTIONS or not rest:
            raise ValueError(f"unknown setting {key!r}")
        try:
            sections[section] = _replaced(sections[section], rest.split("."), value, key)
        except TypeError as exc:
            raise ValueError(f"{section}: {exc}") from None
        except ValueError as exc:
            message = str(exc)
            raise ValueError(message if key in message else f"{key}: {message}") from None
    return replace(config, **top, **sections)


def _plain(value):
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def config_to_dict(config: CalibrationConfig) -> dict[str, Any]:
    """Plain nested dict (YAML/JSON-ready, tuples as lists) of a config."""
    data: dict[str, Any] = {"seed": config.seed}
    for section in SECTIONS:
        data[section] = _plain(getattr(config, section))
    return data


def flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    """Add the leaves of a nested dict to ``out`` as ``{"prefix.a.b": value}``."""
    if isinstance(value, dict):
        for name, item in value.items():
            flatten(f"{prefix}.{name}", item, out)
    else:
        out[prefix] = value


def config_from_dict(
    data: dict[str, Any], base: CalibrationConfig | None = None, *, source=None
) -> CalibrationConfig:
    """Apply a nested dict (:func:`config_to_dict`'s layout, or part of it) to ``base``.

    Raises
    ------
    InputError
        An unknown section or setting, or a value of the wrong type; names ``source``.
    """
    values: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            if key not in SECTIONS:
                raise InputError(
                    f"unknown table [{key}]: tables may be {', '.join(SECTIONS)}", source
                )
            flatten(key, value, values)
        else:
            values[key] = value
    try:
        return set_values(base or CalibrationConfig(), values)
    except ValueError as exc:
        raise InputError(str(exc), source) from None


def read_config_file(path: str | os.PathLike) -> dict[str, Any]:
    """Read a TOML (``.toml``) or YAML (``.yaml``, ``.yml``) config file as a nested dict.

    Raises
    ------
    InputError
        Missing or unreadable file, a syntax error, or a file that is not a table.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("config file not found", path)
    suffix = path.suffix.lower()
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the config file: {exc}", path) from None
    if suffix == ".toml":
        data = _parse_toml(text, path)
    elif suffix in (".yaml", ".yml"):
        data = _parse_yaml(text, path)
    else:
        raise InputError(f"unknown config format '{suffix}': use .toml, .yaml or .yml", path)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError("a config file must be a table of name = value", path)
    return data


def _parse_toml(text: str, path: Path):
    try:
        import tomllib
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib
        except ImportError:
            raise InputError(
                "reading TOML on Python 3.10 needs 'tomli' (pip install tomli); or use YAML", path
            ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"invalid TOML: {exc}", path) from None


def _parse_yaml(text: str, path: Path):
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"invalid YAML: {' '.join(str(exc).split())}", path) from None


def write_config(
    path: str | os.PathLike, config: CalibrationConfig, extra: dict[str, Any] | None = None
) -> None:
    """Write the config used, as YAML that ``--config`` (and :func:`read_config_file`) reads back.

    Parameters
    ----------
    path : str or os.PathLike
        Output file (replaced atomically).
    config : CalibrationConfig
    extra : dict, optional
        Further top-level entries (the job's inputs), written first.
    """
    import yaml

    from nbcalib.io._files import write_text_atomic

    data = {**(extra or {}), **config_to_dict(config)}
    header = (
        "# The settings nbcalib used (defaults included); run again with:\n"
        "#   nbcalib run --config THIS_FILE INPUT... WORKDIR\n"
    )
    text = header + yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
    write_text_atomic(path, text)


def setting_names() -> list[str]:
    """``section.field`` of every setting, in config order (nested ones dotted further)."""
    flat: dict[str, Any] = {}
    for section, value in config_to_dict(CalibrationConfig()).items():
        flatten(section, value, flat)
    return list(flat)


def config_from_record(data) -> CalibrationConfig:
    """The config a work directory recorded (``calib.json``'s ``nbcalib.config``).

    Settings this version does not know, or no longer accepts, are ignored: a record written by
    another version still gives its job's settings where they apply.
    """
    config = CalibrationConfig()
    if not isinstance(data, dict):
        return config
    flat: dict[str, Any] = {}
    for key, value in data.items():
        flatten(key, value, flat)
    try:
        return set_values(config, flat)
    except ValueError:
        for key, value in flat.items():
            try:
                config = set_values(config, {key: value})
            except ValueError:
                continue
        return config
