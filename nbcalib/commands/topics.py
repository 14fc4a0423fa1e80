"""``nbcalib topics BAG [BAG ...]``: what a recording holds, and which topics nbcalib would read.

For each bag: every topic with its message type and count, and for each kind nbcalib reads
(point cloud, image, camera info, tf) the topic ``preprocess`` would choose by itself, or why it
cannot (none, or several: then name one with ``--points-topic`` / ``--image-topic`` /
``--camera-info-topic``). The first step with a recording of your own.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DESCRIPTION = """\
List the topics of ROS 1 / ROS 2 (sqlite3, mcap) bags, with their message types and counts,
and the topic 'nbcalib preprocess' would read for the point clouds, the images and the camera
info (or why it needs you to name one). No ROS installation is needed."""

EPILOG = """\
examples:
  nbcalib topics recording.bag
  nbcalib topics rosbag2_folder/ other.mcap
  nbcalib preprocess recording.bag work --points-topic /ouster/points --image-topic /cam/image
"""

#: The kinds ``preprocess`` reads, and the option that names each one's topic.
KIND_OPTIONS = (
    ("point cloud", "--points-topic"),
    ("image", "--image-topic"),
    ("camera info", "--camera-info-topic"),
)


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``topics`` on the ``nbcalib`` subcommand parser."""
    parser = subparsers.add_parser(
        "topics",
        help="the topics of a bag, and which ones preprocess would read",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    parser.add_argument(
        "bags", metavar="BAG", type=Path, nargs="+", help="a .bag, .db3 or .mcap file or a folder"
    )
    return parser


def describe_bag(path) -> str:
    """The text ``nbcalib topics`` prints for one bag."""
    from nbcalib.io.bag import MESSAGE_KINDS, open_bag

    with open_bag(path) as bag:
        topics, counts = bag.topics, bag.message_counts
        candidates = {kind: bag.candidates(kind) for kind, _ in KIND_OPTIONS}
    width = max((len(t) for t in topics), default=5)
    lines = [f"{path}: {len(topics)} topics"]
    lines += [
        f"  {topic:<{width}}  {msgtype:<32} {counts.get(topic, 0):>6} messages"
        for topic, msgtype in topics.items()
    ]
    lines.append("nbcalib preprocess reads (when no topic option names one):")
    for kind, option in KIND_OPTIONS:
        found = candidates[kind]  # Bag.select_topic's rule: the only one, else name one
        if len(found) == 1:
            chosen = found[0]
        elif found:
            chosen = f"one of {', '.join(found)}: name it with {option}"
        else:
            chosen = f"nothing: no {kind} topic ({', '.join(MESSAGE_KINDS[kind])})"
        lines.append(f"  {kind + ':':<13} {chosen}")
    if len(candidates["image"]) > 1:
        lines.append(
            f"nbcalib run calibrates each of the {len(candidates['image'])} cameras "
            "(--camera-topics to choose some; --rig FILE with known camera-to-camera extrinsics)"
        )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print each bag's topics and the ones preprocess would read; returns 0."""
    for k, path in enumerate(args.bags):
        if k:
            print()
        print(describe_bag(path))
    return 0
