"""Quality of a calibration: uncertainty, verdict and the HTML report (``nbcalib report``).

:func:`assess` works on LiDAR-camera pairs in memory and returns numbers
(:class:`Quality`); :func:`make_report` loads a work directory, runs :func:`assess` and writes
``WORKDIR/report/index.html`` with figures (matplotlib, optional ``viz`` extra).
"""

from nbcalib.report.quality import (
    AXIS_NAMES,
    AssessConfig,
    Quality,
    assess,
    interval_quantiles,
    rejudge,
)

__all__ = [
    "AXIS_NAMES",
    "AssessConfig",
    "Quality",
    "Report",
    "assess",
    "interval_quantiles",
    "make_report",
    "rejudge",
]


def __getattr__(name):
    # the HTML writer pulls in OpenCV and the work-directory code: load it on first use
    if name in ("Report", "make_report"):
        from nbcalib.report import html

        return getattr(html, name)
    raise AttributeError(f"module 'nbcalib.report' has no attribute {name!r}")
