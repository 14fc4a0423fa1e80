"""Quality of a calibration: uncertainty, verdict and the HTML report (``nbcalib report``).

:func:`assess` works on LiDAR-camera pairs in memory and returns numbers (:class:`Quality`,
:mod:`nbcalib.report.quality`); :func:`write_report` writes ``WORKDIR/report/index.html`` with
figures (matplotlib, optional ``viz`` extra; :mod:`nbcalib.report.html`). Settings:
:class:`AssessConfig` (:mod:`nbcalib.report.config`).

Importing this package is cheap: the modules (and numba) load on first use.
"""

from __future__ import annotations

from nbcalib._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    "nbcalib.report",
    {
        "quality": (
            "AXIS_NAMES",
            "Quality",
            "assess",
            "interval_quantiles",
            "load_quality",
            "rejudge",
        ),
        "config": ("AssessConfig",),
        "html": ("Report", "write_report"),
    },
)
