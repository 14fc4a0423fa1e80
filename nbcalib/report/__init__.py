"""Quality of a calibration: uncertainty, verdict and the HTML report (``nbcalib report``).

:func:`assess` works on LiDAR-camera pairs in memory and returns numbers (:class:`Quality`,
:mod:`nbcalib.report.quality`); :func:`write_report` writes ``WORKDIR/report/index.html`` with
figures (matplotlib, optional ``viz`` extra; :mod:`nbcalib.report.html`). Settings:
:class:`AssessConfig` (:mod:`nbcalib.report.config`).

Importing this package is cheap: the modules (and numba) load on first use.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "AXIS_NAMES": "quality",
    "AssessConfig": "config",
    "Quality": "quality",
    "assess": "quality",
    "interval_quantiles": "quality",
    "rejudge": "quality",
    "Report": "html",
    "make_report": "html",
    "write_report": "html",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"nbcalib.report.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'nbcalib.report' has no attribute {name!r}")


def __dir__():
    return __all__
