"""``nbcalib data list|show|verify``: public datasets to calibrate with, and checks of a download.

The facts live in the data manifests (:mod:`nbcalib.data`); nothing here downloads.
``verify`` exits 2 with one line naming the file when a file is missing or its size or SHA-256
differs, and otherwise prints the ``nbcalib run`` command for the downloaded copy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DESCRIPTION = """\
Public LiDAR-camera datasets: where to download them, licence, size, sensors, topics, camera
intrinsics and published reference extrinsics (data manifests, one YAML file per dataset).
'verify' checks a downloaded copy (files present, sizes, SHA-256 where published) and prints
the exact 'nbcalib run' command for it. Nothing is ever downloaded by nbcalib."""

EPILOG = """\
examples:
  nbcalib data list                                  # table: name, sensors, size, licence
  nbcalib data show kitti_raw_2011_09_26             # everything known about one dataset
  nbcalib data verify dvlc_livox ~/data/dvlc         # check a download, print the run command
  nbcalib data verify my_rig.yaml ~/data/rig --workdir work/rig   # your own manifest file
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``data`` (with ``list``, ``show``, ``verify``) on the subcommand parser."""
    parser = subparsers.add_parser(
        "data",
        help="public datasets: list, show, verify a download",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    sub = parser.add_subparsers(dest="data_command", metavar="ACTION", parser_class=type(parser))
    manifests_help = "folder of manifest files (default: the ones shipped with nbcalib)"

    p_list = sub.add_parser(
        "list",
        help="table of the known datasets",
        description="List the known datasets: name, sensors, size and licence.",
        epilog="examples:\n  nbcalib data list\n  nbcalib data list --manifests my_manifests/\n",
        formatter_class=formatter_class,
    )
    p_list.add_argument("--manifests", metavar="DIR", type=Path, help=manifests_help)

    p_show = sub.add_parser(
        "show",
        help="everything known about one dataset",
        description="Show one dataset's manifest: downloads, licence, sensors, topics, camera, "
        "reference extrinsic, files and the nbcalib run command.",
        epilog="examples:\n  nbcalib data show dvlc_ouster\n  nbcalib data show my_rig.yaml\n",
        formatter_class=formatter_class,
    )
    p_show.add_argument("name", metavar="NAME", help="dataset name or manifest file (.yaml)")
    p_show.add_argument("--manifests", metavar="DIR", type=Path, help=manifests_help)

    p_verify = sub.add_parser(
        "verify",
        help="check a downloaded copy and print its nbcalib run command",
        description="Check that DIR holds the dataset's files (sizes and SHA-256 where the "
        "manifest knows them; an unpacked archive counts as present) and print the exact "
        "'nbcalib run' command. Exit status 2 with one line naming the file on a mismatch.",
        epilog="examples:\n  nbcalib data verify kitti_raw_2011_09_26 ~/data/kitti\n"
        "  nbcalib data verify opencalib_auto_calib ~/data/opencalib --no-hash\n",
        formatter_class=formatter_class,
    )
    p_verify.add_argument("name", metavar="NAME", help="dataset name or manifest file (.yaml)")
    p_verify.add_argument("directory", metavar="DIR", type=Path, help="where the data was saved")
    p_verify.add_argument(
        "--workdir",
        metavar="WORKDIR",
        default=None,
        help="work directory for the printed run command (default: <NAME>_work)",
    )
    p_verify.add_argument("--no-hash", action="store_true", help="check sizes only (faster)")
    p_verify.add_argument(
        "--no-progress", action="store_true", help="no progress display while hashing"
    )
    p_verify.add_argument("--manifests", metavar="DIR", type=Path, help=manifests_help)
    parser.set_defaults(data_parser=parser)
    return parser


def run(args: argparse.Namespace) -> int:
    """Dispatch to the ``data`` action; returns the exit status."""
    if args.data_command is None:
        args.data_parser.print_help()
        return 2
    return {"list": _list, "show": _show, "verify": _verify}[args.data_command](args)


def _list(args) -> int:
    from nbcalib.data import list_manifests

    manifests = list_manifests(args.manifests)
    rows = [("NAME", "SENSORS", "SIZE", "LICENCE")]
    rows += [(m.name, m.sensors_text, m.size_text, m.licence) for m in manifests]
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    for row in rows:
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths)) + "  " + row[3])
    print(f"\n{len(manifests)} datasets; 'nbcalib data show NAME' for details.")
    return 0


def _show(args) -> int:
    from nbcalib.data import find_manifest

    manifest = find_manifest(args.name, args.manifests)
    print(format_manifest(manifest))
    return 0


def _verify(args) -> int:
    from nbcalib.data import find_manifest, verify_dataset
    from nbcalib.errors import InputError

    manifest = find_manifest(args.name, args.manifests)
    checks = verify_dataset(
        manifest, args.directory, hashes=not args.no_hash, progress=not args.no_progress
    )
    print(f"{manifest.name}: {args.directory}")
    for check in checks:
        print(f"  {check.status:<13} {check.file.path}: {check.detail}")
    failed = [check for check in checks if check.failed]
    if failed:
        first = failed[0]
        more = f" ({len(failed) - 1} more problem(s) listed above)" if len(failed) > 1 else ""
        raise InputError(
            f"{first.status.replace('_', ' ')}: {first.detail}{more}",
            Path(args.directory) / first.file.path,
        )
    workdir = args.workdir or f"{manifest.name}_work"
    print("\nAll files present. Calibrate with:\n")
    print(f"  {manifest.run_command(args.directory, workdir)}")
    return 0


def format_manifest(manifest) -> str:
    """The text ``nbcalib data show`` prints for a :class:`~nbcalib.data.Manifest`."""
    d = manifest.data
    lines = [f"{manifest.name}: {d['title']}", "", _wrap(d["description"]), ""]
    add = lines.extend

    add(_field("homepage", d["homepage"]))
    for url in d["downloads"]:
        add(_field("download", url))
    licence = d["licence"]
    text = manifest.licence + (f" ({licence['url']})" if licence["url"] else "")
    add(_field("licence", text + (f"; {licence['note']}" if licence.get("note") else "")))
    add(_field("size", manifest.size_text))
    lidar, camera_sensor = d["sensors"]["lidar"], d["sensors"]["camera"]
    text = f"{lidar['kind']}, {lidar['model'] or 'model not stated'}"
    add(_field("lidar", text + (f"; {lidar['note']}" if lidar.get("note") else "")))
    text = camera_sensor["model"] or "model not stated"
    add(
        _field("camera", text + (f"; {camera_sensor['note']}" if camera_sensor.get("note") else ""))
    )
    if d["topics"]:
        add(_field("topics", ", ".join(f"{k} {v}" for k, v in d["topics"].items() if v)))
    camera = d["camera"]
    if camera:
        size = f"{camera['width']} x {camera['height']}" if camera["width"] else "size not stated"
        text = (
            f"{camera['camera_model']}, {size}, intrinsics {camera['intrinsics']}, "
            f"distortion {camera['distortion_coeffs']}; source {camera['source']}"
        )
        add(_field("intrinsics", text))
    extrinsic = d["reference_extrinsic"]
    if extrinsic:
        text = (
            f"T_lidar_camera [x, y, z, qx, qy, qz, qw] = {extrinsic['T_lidar_camera']} "
            f"(p_lidar = T_lidar_camera p_camera); source {extrinsic['source']}"
        )
        add(_field("extrinsic", text + (f"; {extrinsic['note']}" if extrinsic.get("note") else "")))
    else:
        add(_field("extrinsic", "none published"))
    lines.append("files:")
    for entry in manifest.files:
        size = f"{entry.bytes} bytes" if entry.bytes is not None else "size unknown"
        digest = f"sha256 {entry.sha256}" if entry.sha256 else "no published hash"
        optional = ", optional" if entry.optional else ""
        lines.append(f"  {entry.path} ({size}, {digest}{optional})")
    add(_field("run", " ".join(d["run"].split())))
    if d.get("notes"):
        add(_field("notes", d["notes"]))
    lines += ["sources:"] + [f"  {url}" for url in d["sources"]]
    add(_field("manifest", str(manifest.path)))
    return "\n".join(lines)


def _field(label: str, text: str) -> list[str]:
    """``label:`` and ``text`` wrapped at 100 columns under a hanging indent."""
    import textwrap

    return textwrap.wrap(
        " ".join(str(text).split()),
        width=100,
        initial_indent=f"{label + ':':<12}",
        subsequent_indent=" " * 12,
        break_long_words=False,
        break_on_hyphens=False,
    )


def _wrap(text: str) -> str:
    import textwrap

    return textwrap.fill(" ".join(text.split()), width=100)
