"""The report of a several-camera job: one page, a section per camera and one for the rig.

``WORK/report/index.html`` (:func:`write_rig_report`) gathers what each camera's own report
(``WORK/<camera>/report/index.html``, :mod:`nbcalib.report.html`) says: its verdict, result,
uncertainty and move from its start, with its overlay figures shown from its folder, and a
link to the whole camera report; then the rig: each camera in the reference camera's frame, as
given (``--rig``: one pose from every camera) or as the LiDAR results imply, and how far the
implied transforms are from given ones.
"""

from __future__ import annotations

import html
import time
from pathlib import Path

from nbcalib.io._files import write_text_atomic
from nbcalib.report.html import _STYLE  # one look for the job's page and each camera's

__all__ = ["write_rig_report"]


def _values(values) -> str:
    return "[" + ", ".join(f"{v:.6f}" for v in values) + "]"


def _camera_section(workdir: Path, name: str, entry: dict) -> str:
    from nbcalib.io.calib_json import FINAL_STAGE, read_calib_json

    folder = workdir / name
    calib_path = folder / "calib.json"
    head = f"<h2 id='{html.escape(name)}'>Camera {html.escape(name)}</h2>"
    topic = html.escape(str(entry.get("image_topic") or ""))
    if not calib_path.is_file():
        return head + "<p>No work directory yet.</p>"
    calib = read_calib_json(calib_path)
    record = calib.record
    model = record.camera.model if record.camera is not None else "?"
    size = record.camera.size if record.camera is not None else None
    lines = [
        f"<p>Image topic <code>{topic}</code>; {html.escape(str(model))} camera"
        + (f", {size[0]} x {size[1]} pixels" if size else "")
        + f"; work directory <code>{html.escape(str(folder))}</code>.</p>"
    ]
    if not calib.has_result(FINAL_STAGE):
        return head + "".join(lines) + "<p>No calibration result yet.</p>"
    lines.append(f"<p>T_lidar_camera: <code>{_values(calib.results[FINAL_STAGE])}</code></p>")
    calibration = record.calibration
    if calibration is not None and calibration.figures.get("adopted_from"):
        lines.append(
            f"<p>Result: {html.escape(str(calibration.figures['adopted_from']))} "
            f"(this camera's own start: {html.escape(str(calibration.start))}).</p>"
        )
    quality = record.quality
    if quality is None:
        return head + "".join(lines) + "<p>No report yet.</p>"
    figures = quality.figures
    verdict = str(figures.get("verdict", "?"))
    u = figures.get("uncertainty") or {}
    t_total, r_total = u.get("translation_total_cm"), u.get("rotation_total_deg")
    bound = (
        f"; uncertainty &le; {t_total:.2f} cm, {r_total:.3f} deg"
        if isinstance(t_total, (int, float)) and isinstance(r_total, (int, float))
        else ""
    )
    lines.append(
        f"<p>Verdict: <span class='{html.escape(verdict)}'>{html.escape(verdict)}</span>"
        f"{bound}. <a href='../{html.escape(name)}/report/index.html'>The camera's report</a>"
        "</p>"
    )
    reasons = figures.get("reasons") or []
    if reasons:
        lines.append("<ul>" + "".join(f"<li>{html.escape(str(r))}</li>" for r in reasons) + "</ul>")
    report = folder / "report"
    for image in sorted(report.glob("overlay_*.png")):
        lines.append(
            f"<img src='../{html.escape(name)}/report/{html.escape(image.name)}' "
            f"alt='{html.escape(image.name)}'/>"
        )
    return head + "".join(lines)


def _rig_section(job: dict) -> str:
    ref = html.escape(str(job.get("reference", "")))
    joint = bool(job.get("joint"))
    how = (
        "given (run.rig): one rig pose refined from every camera's pairs, each camera's result "
        "that pose through the rig"
        if joint
        else "as the cameras' own results imply"
    )
    errors = job.get("rig_errors") or {}
    rows = []
    for entry in job["cameras"]:
        name = entry["name"]
        values = entry.get("T_ref_camera")
        off = errors.get(name)
        rows.append(
            f"<tr><td style='text-align:left'>{html.escape(name)}</td>"
            f"<td><code>{_values(values) if values else 'no result'}</code></td>"
            + (
                f"<td>{100 * off['translation_m']:.2f} cm, {off['rotation_deg']:.3f} deg</td>"
                if off
                else ("<td>-</td>" if errors else "")
            )
            + "</tr>"
        )
    head = "<th>from the given rig</th>" if errors else ""
    return (
        f"<h2>The rig</h2><p>Each camera in the reference camera {ref}'s frame, "
        f"T_{ref}_camera (x, y, z in m; qx, qy, qz, qw), {how}.</p>"
        f"<table><tr><th>camera</th><th>T_{ref}_camera</th>{head}</tr>{''.join(rows)}</table>"
    )


def write_rig_report(workdir, job: dict) -> Path:
    """Write ``WORK/report/index.html`` for a several-camera job (``rig.json``'s content)."""
    workdir = Path(workdir)
    names = [c["name"] for c in job["cameras"]]
    summary = "".join(f"<li><a href='#{html.escape(n)}'>{html.escape(n)}</a></li>" for n in names)
    stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    page = (
        "<!DOCTYPE html>\n<html><head><meta charset='utf-8'>"
        f"<title>nbcalib report: {html.escape(workdir.name)}</title>"
        f"<style>{_STYLE}</style></head><body>"
        f"<h1>Calibration report: {html.escape(str(workdir))}, {len(names)} cameras</h1>"
        f"<ul>{summary}</ul>"
        f"{_rig_section(job)}"
        + "".join(_camera_section(workdir, n, c) for n, c in zip(names, job["cameras"]))
        + f"<p class='note'>Written by nbcalib at {stamp}; the job is in rig.json, each "
        "camera's numbers in its calib.json.</p></body></html>\n"
    )
    path = workdir / "report" / "index.html"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, page)
    return path
