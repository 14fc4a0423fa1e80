"""``WORKDIR/report/index.html``: the quality report of a calibrated work directory.

:func:`write_report` writes the HTML page of an assessed result (:func:`nbcalib.report.
quality.assess`) with its PNG figures, and stores the quality figures in ``calib.json`` under
``nbcalib.quality`` (the reference's keys are not touched). It renders from the products and
records it is given: the report stage of :class:`nbcalib.pipeline.Calibrator` calls it
(:func:`nbcalib.pipeline.make_report` for a work directory as ``nbcalib report`` does).

**Crash safety.** The report is written into a hidden temporary folder next to ``report/``
(figures first, ``index.html`` last) that replaces ``report/`` by renames only when it is
complete, so a report folder with an ``index.html`` is always a whole one. ``calib.json`` is
updated afterwards, atomically.

Without matplotlib (optional ``viz`` extra) the page holds the numbers only and says so.
"""

from __future__ import annotations

import base64
import html
import math
import os
import shutil
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.errors import MissingExtraError, require
from nbcalib.io._files import write_bytes_atomic, write_text_atomic
from nbcalib.io.calib_json import FINAL_STAGE
from nbcalib.io.job_record import QualityRecord
from nbcalib.progress import Progress
from nbcalib.report.quality import AXIS_NAMES, Quality, format_bound

__all__ = ["REPORT_DIR", "Report", "move_summary", "write_report"]

#: Folder of the report inside the work directory.
REPORT_DIR = "report"
#: Pairs that get overlay and edge figures (the first ones).
MAX_PAIRS_DRAWN = 4


@dataclass
class Report:
    """Where the report went and what it says.

    Attributes
    ----------
    html_path : Path
        ``WORKDIR/report/index.html``.
    verdict : {"ok", "suspect"}
    reasons : list of str
    uncertainty : dict
        As :attr:`nbcalib.report.quality.Quality.uncertainty` (cm and degrees).
    quality : Quality
    figures : list of Path
        The PNG files written (empty without matplotlib).
    """

    html_path: Path
    verdict: str
    reasons: list[str]
    uncertainty: dict
    quality: Quality = field(repr=False)
    figures: list[Path] = field(default_factory=list)

    def _repr_html_(self) -> str:
        """Summary and figures inline, for notebooks."""
        images = "".join(
            f'<img style="max-width:100%" src="data:image/png;base64,'
            f'{base64.b64encode(p.read_bytes()).decode()}"/>'
            for p in self.figures
            if p.is_file()
        )
        return _summary_html(self.quality) + images


def write_report(
    work,
    quality: Quality,
    loaded,
    pairs,
    T_camera_lidar,
    T_init,
    refine_config,
    init_stage: str | None,
    *,
    progress: bool | Callable[[str], None] | None = None,
) -> Report:
    """Write ``report/index.html`` with its figures, and the figures into ``calib.json``.

    Parameters
    ----------
    work : WorkDir
        The work directory.
    quality : Quality
        :func:`~nbcalib.report.quality.assess`'s result for ``T_camera_lidar``.
    loaded : sequence of PairData
        The pairs' products (camera image, LiDAR image and index map).
    pairs : sequence of RegistrationPair
        The same pairs as registration saw them.
    T_camera_lidar : ndarray of shape (4, 4)
        The result judged.
    T_init : ndarray of shape (4, 4) or None
        Where fine registration started.
    refine_config : RefineConfig
        Its settings (hidden-point removal for the overlays).
    init_stage : str or None
        Name of the start (``init_T_lidar_camera_auto``, ``--init``...), shown on the page.
    progress : bool or callable, optional
        ``True`` for a progress display (:class:`nbcalib.progress.Progress`: a bar on a
        terminal, step lines in a log, nothing when the ``nbcalib`` logger is quiet), or a
        callback called with the name of each file written.
    """
    try:
        require("matplotlib", "viz")
        have_mpl = True
    except MissingExtraError:
        have_mpl = False
    n_figures = 2 + 2 * min(len(loaded), len(pairs), MAX_PAIRS_DRAWN) if have_mpl else 0
    with Progress(n_figures + 2, "report", enabled=progress is True) as display:

        def step(what: str) -> None:
            if callable(progress):
                progress(what)
            display.update(what=what)

        T = np.asarray(T_camera_lidar, dtype=np.float64)
        final = work.path / REPORT_DIR
        tmp = work.path / f".{REPORT_DIR}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp"
        tmp.mkdir()
        try:
            figures = []
            if have_mpl:
                figures = _write_figures(
                    tmp, quality, loaded, pairs, refine_config, T, T_init, step
                )
            quality.save(tmp / "quality.npz")  # the material to judge it again (rejudge)
            info = work.read_calib().record.calibration
            refined = None if info is None else info.figures.get("intrinsics")
            page = _page(quality, work.path, figures, have_mpl, init_stage, refined)
            write_text_atomic(tmp / "index.html", page)  # last: marks the folder complete
            step("index.html")
            _swap_in(tmp, final)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise

        calib = work.read_calib()  # re-read: keep whatever changed meanwhile
        calib.record.quality = QualityRecord.make(
            quality.to_dict(),
            page=f"{REPORT_DIR}/index.html",
            written=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            assessed=list(calib.results.get(FINAL_STAGE, [])),
        )
        from nbcalib.io.calib_json import write_calib_json

        write_calib_json(work.calib_path, calib)
        step("calib.json")
    return Report(
        html_path=final / "index.html",
        verdict=quality.verdict,
        reasons=list(quality.reasons),
        uncertainty=dict(quality.uncertainty),
        quality=quality,
        figures=[final / f.name for f in figures],
    )


def _swap_in(tmp: Path, final: Path) -> None:
    """Replace ``final`` by the finished folder ``tmp`` with renames only."""
    old = None
    if final.exists():
        old = final.with_name(f".{final.name}.old.{uuid.uuid4().hex[:8]}")
        os.replace(final, old)
    os.replace(tmp, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _write_figures(folder: Path, quality, loaded, pairs, config, T, T_init, step) -> list[Path]:
    from nbcalib.registration.refine import visible_subset
    from nbcalib.report import figures as fg

    written = []

    def save(name: str, data: bytes) -> None:
        path = folder / name
        write_bytes_atomic(path, [data])
        written.append(path)
        step(name)

    save("nid_curves.png", fg.nid_curves(quality))
    save("pairs_uncertainty.png", fg.pairs_and_uncertainty(quality))
    for k, (work_pair, pair) in enumerate(zip(loaded, pairs)):
        if k >= MAX_PAIRS_DRAWN:
            break
        with pair.held():  # a cloud read from the work directory: once for its figures
            # the result's visible set first: the report's cost has it already
            result = visible_subset(pair, T, config)
            poses = []
            if T_init is not None:
                poses.append(("initial guess", T_init, visible_subset(pair, T_init, config)))
            poses.append(("result", T, result))
            stem = _safe(pair.name or str(k))
            points, intensities = pair.cloud.arrays()  # float64 once for the three figures
            edges = fg.lidar_edge_points(
                work_pair.lidar_image.intensity, work_pair.lidar_index, points
            )
            save(
                f"alignment_{stem}.png",
                fg.alignment(pair.camera, work_pair.image, points, edges, T, result),
            )
            save(
                f"overlay_{stem}.png",
                fg.overlays(pair.camera, work_pair.image, points, intensities, poses),
            )
            save(
                f"edges_{stem}.png",
                fg.edge_overlay(pair.camera, work_pair.image, points, edges, poses),
            )
    return written


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)[:80]


# ------------------------------------------------------------------------------ HTML

_STYLE = """
body { font-family: sans-serif; margin: 2em; max-width: 1200px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
td, th { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f3f3f3; }
.ok { color: #fff; background: #2a7d2a; padding: 0.2em 0.6em; border-radius: 4px; }
.suspect { color: #fff; background: #b03a2e; padding: 0.2em 0.6em; border-radius: 4px; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.3em 0 1em; }
.note { color: #666; font-size: 0.9em; }
.warn { border-left: 4px solid #b03a2e; padding-left: 0.6em; }
"""


def _axis(value: float, unit: str) -> str:
    """One axis's half-width for the table: the number, or "unbounded"."""
    text = format_bound(value, unit)
    return "unbounded" if text.startswith("unbounded") else text.removesuffix(f" {unit}")


def _summary_html(q: Quality) -> str:
    u = q.uncertainty
    conf = 100 * u.get("confidence", 0.95)
    reasons = "".join(f"<li>{html.escape(r)}</li>" for r in q.reasons) or "<li>none</li>"
    steps = "".join(f"<li>{html.escape(s)}</li>" for s in q.next_steps)
    t = [_axis(x, "cm") for x in u["translation_cm"]]
    r = [_axis(x, "deg") for x in u["rotation_deg"]]
    t_total = format_bound(u["translation_total_cm"], "cm").removesuffix(" cm")
    r_total = format_bound(u["rotation_total_deg"], "deg").removesuffix(" deg")
    return (
        f'<h2>Verdict: <span class="{q.verdict}">{q.verdict}</span></h2>'
        f"<p>Reasons to distrust the result:</p><ul>{reasons}</ul>"
        + (f"<p>What to do next:</p><ul>{steps}</ul>" if q.next_steps else "")
        + f"<h2>Uncertainty ({conf:.0f} %)</h2>"
        "<table><tr><th></th><th>x (right)</th><th>y (down)</th><th>z (forward)</th>"
        "<th>total (norm)</th></tr>"
        f"<tr><th>translation, cm</th><td>&plusmn;{t[0]}</td><td>&plusmn;{t[1]}</td>"
        f"<td>&plusmn;{t[2]}</td><td>&le; {html.escape(t_total)}</td></tr>"
        f"<tr><th>rotation, deg</th><td>&plusmn;{r[0]}</td><td>&plusmn;{r[1]}</td>"
        f"<td>&plusmn;{r[2]}</td><td>&le; {html.escape(r_total)}</td></tr></table>"
        f'<p class="note">Camera axes; translation = displacement of the camera centre. '
        f"Method: {html.escape(str(u.get('method', '')))}.</p>"
    )


def move_summary(q: Quality) -> str:
    """One line on the move from the start: how far, what the uncertainties allow, the region.

    Empty when the start is not known.
    """
    if q.init_change is None:
        return ""
    dt, dr = q.init_change
    text = f"moved {100 * dt:.2f} cm, {dr:.3f} deg from the start"
    if q.move_allowed is not None:
        used = q.start_uncertainty_used
        whose = "stated" if used[1] == "stated" else "none stated: the trust region"
        text += (
            f" (the start's uncertainty, {whose}, {100 * used[0][0]:.1f} cm / {used[0][1]:.2f} "
            f"deg, and the result's allow {100 * q.move_allowed[0]:.1f} cm / "
            f"{q.move_allowed[1]:.2f} deg)"
        )
    if q.trust_region is not None:
        edge = "ON ITS EDGE" if q.at_trust_boundary else "inside"
        text += (
            f"; trust region {100 * q.trust_region[0]:.1f} cm / {q.trust_region[1]:.2f} deg: {edge}"
        )
    return text


def _move_html(q: Quality, init_stage) -> str:
    if q.init_change is None:
        return ""
    line = move_summary(q)
    return (
        f"<h2>Move from the start</h2><p>The result {html.escape(line)}. Start: "
        f"{html.escape(str(init_stage))}.</p>"
        '<p class="note">A result on the trust region\'s edge may have been held there short of '
        "its optimum; a move beyond what the two uncertainties allow (sqrt(s&sup2; + "
        "u&sup2;) at the report's confidence) means the start or the result is off by more "
        "than stated (docs/pipeline.md, Report).</p>"
    )


def _intrinsics_html(entry: dict | None, check: dict | None = None) -> str:
    """The intrinsics: refined with the extrinsic (``refine.intrinsics``), or checked."""
    if not isinstance(entry, dict):
        if not isinstance(check, dict) or not check.get("note"):
            return ""
        flag = "" if check.get("agrees", True) else ' class="warn"'
        return f"<h2>Intrinsics</h2><p{flag}>{html.escape(str(check['note']))}.</p>"
    try:
        scale = float(entry["focal_scale"])
        found = (
            f"focal length x{scale:.4f} ({100 * (scale - 1):+.2f} %, +-"
            f"{float(entry['focal_bound_percent']):.2f} %)"
        )
        if entry.get("mode") == "focal,center":
            dx, dy = entry["center_shift_px"]
            found += (
                f", principal point moved {dx:+.1f}, {dy:+.1f} px (+-"
                f"{float(entry['center_bound_px']):.1f} px)"
            )
        corr = float(entry["correlation_focal_forward"])
        camera = entry["camera"] if entry.get("refined") else entry["given_camera"]
        used = ", ".join(f"{float(x):.2f}" for x in camera["intrinsics"])
    except (KeyError, TypeError, ValueError):
        return ""
    if entry.get("refined"):
        verdict = f"The result goes with the refined camera (intrinsics {used})."
    else:
        verdict = (
            f"The given camera is kept (intrinsics {used}), and the pose found with it: "
            f"{entry.get('reason', '')}."
        )
    return (
        f"<h2>Intrinsics</h2><p>Refined with the extrinsic over every pair: {found}, at the "
        f"report's 95 % bounds from leaving each pair out. {html.escape(verdict)}</p>"
        f"<p>Correlation of focal length and forward translation: {corr:+.2f}. Near +-1 the "
        "frames cannot tell a longer focal length from a camera further forward (frames at "
        "one depth, or too few).</p>"
    )


def _page(
    q: Quality,
    workdir: Path,
    figures: list[Path],
    have_mpl: bool,
    init_stage,
    intrinsics: dict | None = None,
) -> str:
    from nbcalib.io.calib_json import values_from_T_camera_lidar

    xyzq = values_from_T_camera_lidar(q.T_camera_lidar)
    rows = "".join(
        f"<tr><td style='text-align:left'>{html.escape(n)}</td><td>{nid:.4f}</td>"
        f"<td>{v}</td><td>{p}</td>"
        + (
            "<td>"
            + ", ".join(
                f"{100 * x:+.2f}" if a < 3 else f"{math.degrees(x):+.3f}"
                for a, x in enumerate(q.pair_offsets[i])
            )
            + "</td>"
            if q.pair_offsets is not None
            else ""
        )
        + "</tr>"
        for i, (n, nid, v, p) in enumerate(
            zip(q.names, q.nid_per_pair, q.visible_points, q.pixels_covered)
        )
    )
    offsets_head = (
        "<th>own optimum - result (tx, ty, tz cm; rx, ry, rz deg)</th>"
        if q.pair_offsets is not None
        else ""
    )
    spread = ""
    if q.pair_offsets is not None:
        sd = np.std(q.pair_offsets, axis=0, ddof=1)
        spread = (
            "<p>Spread between pairs (standard deviation of their own optima): "
            + ", ".join(
                f"{AXIS_NAMES[a]} {100 * sd[a]:.2f} cm"
                if a < 3
                else f"{AXIS_NAMES[a]} {math.degrees(sd[a]):.3f} deg"
                for a in range(6)
            )
            + "</p>"
        )
    init = _move_html(q, init_stage)
    conv = {True: "yes", False: "no", None: "unknown"}[q.converged]
    stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    if have_mpl:
        figs = "".join(
            f'<h3>{html.escape(_caption(p.name))}</h3><img src="{html.escape(p.name)}" '
            f'alt="{html.escape(p.name)}"/>'
            for p in figures
        )
    else:
        figs = (
            '<p class="note">matplotlib is not installed, so this report has numbers only; '
            'install the figures with <code>pip install "nbcalib[viz]"</code> and run '
            "<code>nbcalib report</code> again.</p>"
        )
    return (
        "<!DOCTYPE html>\n<html><head><meta charset='utf-8'>"
        f"<title>nbcalib report: {html.escape(workdir.name)}</title>"
        f"<style>{_STYLE}</style></head><body>"
        f"<h1>Calibration report: {html.escape(str(workdir))}</h1>"
        "<p>T_lidar_camera (x, y, z in m; qx, qy, qz, qw): "
        f"<code>[{', '.join(f'{v:.6f}' for v in xyzq)}]</code></p>"
        f"{_summary_html(q)}{_intrinsics_html(intrinsics, q.intrinsics_check)}"
        f"<h2>Pairs</h2><p>Summed NID {q.nid:.4f}; optimiser converged: {conv}.</p>{init}"
        "<table><tr><th>pair</th><th>NID</th><th>visible points</th><th>pixels covered</th>"
        f"{offsets_head}</tr>{rows}</table>{spread}"
        f"<h2>Figures</h2>{figs}"
        f'<p class="note">Written by nbcalib at {stamp}'
        "; the numbers are also in calib.json under nbcalib.quality.</p>"
        "</body></html>\n"
    )


def _caption(name: str) -> str:
    if name == "nid_curves.png":
        return "NID along each axis around the result"
    if name == "pairs_uncertainty.png":
        return "Per-pair NID and the uncertainty"
    if name.startswith("alignment_"):
        return (
            f"Alignment: LiDAR edges on the image at full width and zoomed where the structure "
            f"is (judge 1-2 px here): {name[10:-4]}"
        )
    if name.startswith("overlay_"):
        return f"LiDAR points on the image, by range and intensity: {name[8:-4]}"
    if name.startswith("edges_"):
        return f"Edges: image vs LiDAR (intensity and depth): {name[6:-4]}"
    return name
