"""Config files of the command line: TOML or YAML, keys = long option names.

A config file holds the options of ``nbcalib run`` (and so of every stage) that a job always
uses, for example::

    # job.toml
    camera = "camera.yaml"          # = --camera camera.yaml
    dynamic = true                  # = --dynamic
    matcher = "sift"

    [calibrate]                     # tables named after a stage are only for readability
    optimizer = "nelder_mead"
    bins = 16

Keys are long option names, with or without the leading ``--``, ``-`` and ``_`` alike
(``voxel-size``, ``voxel_size``); ``inputs`` lists the positional inputs. Options given on the
command line win over the file. The values a run used (defaults included) are written into the
work directory as ``nbcalib_config.yaml`` (:func:`write_config`), which ``--config`` reads back,
and under ``nbcalib.config`` of ``calib.json``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from nbcalib.errors import InputError

__all__ = ["CONFIG_FILE", "STAGE_TABLES", "load_config", "option_name", "write_config"]

#: File name of the used configuration inside a work directory.
CONFIG_FILE = "nbcalib_config.yaml"

#: Table names that group options by stage; they are flattened on loading.
STAGE_TABLES = ("run", "preprocess", "find-matches", "initial-guess", "calibrate", "report")


def option_name(key: str) -> str:
    """The long option a config key stands for: ``voxel_size`` -> ``--voxel-size``."""
    return "--" + str(key).lstrip("-").replace("_", "-")


def load_config(path: str | os.PathLike) -> dict[str, Any]:
    """Read a TOML (``.toml``) or YAML (``.yaml``, ``.yml``) config file.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    dict
        Long option name (``--voxel-size``) -> value; stage tables flattened.

    Raises
    ------
    InputError
        Missing or unreadable file, a syntax error, a value that is a table outside the stage
        tables, or one option given twice (in two tables) with different values.
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
        raise InputError("a config file must be a table of option = value", path)
    options: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            if option_name(key)[2:] not in STAGE_TABLES:
                raise InputError(
                    f"unknown table [{key}]: tables may only be {', '.join(STAGE_TABLES)}", path
                )
            items = value.items()
        else:
            items = [(key, value)]
        for name, item in items:
            option = option_name(name)
            if isinstance(item, dict):
                raise InputError(f"{option}: expected a value, got a table", path)
            if option in options and options[option] != item:
                raise InputError(f"{option} is given twice, with different values", path)
            options[option] = item
    return options


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


def write_config(path: str | os.PathLike, sections: dict[str, dict[str, Any]]) -> None:
    """Write the used options, one table per stage, as YAML that :func:`load_config` reads back.

    Parameters
    ----------
    path : str or os.PathLike
        Output file (replaced atomically).
    sections : dict of str to dict
        Stage name (:data:`STAGE_TABLES`) -> option name (``voxel_size`` or ``--voxel-size``)
        -> value (None, bool, int, float, str, or a list of them).
    """
    import yaml

    from nbcalib.io._files import write_text_atomic

    data = {
        stage: {option_name(k)[2:]: _plain(v) for k, v in values.items()}
        for stage, values in sections.items()
    }
    header = (
        "# Options used by nbcalib (defaults included); re-run with: nbcalib run --config "
        "THIS_FILE INPUT... WORKDIR\n"
    )
    text = header + yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
    write_text_atomic(path, text)


def _plain(value):
    """A YAML-safe copy: paths to str, tuples to lists."""
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
