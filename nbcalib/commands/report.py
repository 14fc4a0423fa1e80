"""``nbcalib report WORKDIR``: overlays, cost landscapes, uncertainty and a verdict."""

from __future__ import annotations

import argparse

from nbcalib.errors import FAILED_STATUS

DESCRIPTION = """\
Judge the calibration of a work directory and write WORKDIR/report/index.html: LiDAR points on
the image (by range and by intensity) before and after refinement, image edges against LiDAR
edges, the NID along each of the six axes around the result, per-pair NID and their spread, an
uncertainty in centimetres and degrees, and a verdict, ok or suspect, with its reasons. The
figures need matplotlib (pip install "nbcalib[viz]"); without it the page has numbers only.
The page and the printout also show how far the result moved from its start, against what the
start's uncertainty (--init-uncertainty, else the trust region) and the result's allow, and
whether it ended on the edge of the trust region (both make the verdict suspect).
The quality figures are also stored in calib.json under nbcalib.quality.
Prints the verdict on stdout; exits 0 whatever the verdict (--strict: 3 when suspect).
"""

EPILOG = """\
examples:
  nbcalib report work/
  nbcalib report work/ --confidence 0.99
  nbcalib report work/ --restarts 0     # faster: no restarts around the result
  nbcalib calibrate work/ && nbcalib report work/ --strict || echo "check the result"
"""

#: Exit status of ``--strict`` when the verdict is "suspect" (a result not to trust, as a
#: fine registration that failed).
SUSPECT_STATUS = FAILED_STATUS


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``report``."""
    from nbcalib.commands._options import ASSESS, add_options

    p = subparsers.add_parser(
        "report",
        help="quality report: overlays, NID curves, uncertainty, verdict (HTML)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    p.add_argument("workdir", metavar="WORKDIR", help="work directory after nbcalib calibrate")
    add_options(p, ASSESS)
    p.add_argument(
        "--strict", action="store_true", help=f"exit {SUSPECT_STATUS} when the verdict is suspect"
    )
    return p


def run(args) -> int:
    """Write the report and print the verdict."""
    from nbcalib.commands._args import stage_calibrator

    calibrator = stage_calibrator(args, ("assess",))
    calibrator.run(only="report")
    report = calibrator.report
    print_verdict(report)
    return SUSPECT_STATUS if args.strict and report.verdict == "suspect" else 0


def print_verdict(report) -> None:
    """The verdict, its reasons, the uncertainty and where the report is (``nbcalib run`` too)."""
    from nbcalib.report.html import move_summary
    from nbcalib.report.quality import format_bound

    u = report.uncertainty
    move = move_summary(report.quality)
    print(
        f"verdict: {report.verdict}"
        + "".join(f"\n  - {reason}" for reason in report.reasons)
        + "".join(f"\n  next: {step}" for step in report.quality.next_steps)
        + f"\nuncertainty ({100 * u['confidence']:.0f} %): translation <= "
        f"{format_bound(u['translation_total_cm'], 'cm')}, rotation <= "
        f"{format_bound(u['rotation_total_deg'], 'deg')}"
        + (f"\n{move}" if move else "")
        + f"\nreport: {report.html_path}"
    )
