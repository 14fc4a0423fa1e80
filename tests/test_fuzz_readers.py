"""Fuzzing the file readers: a bad input is an InputError naming the file, never another error.

Structure-aware: each example starts from a valid file, written by nbcalib's writers or built
here from the format description, and mutates it: truncated at a random offset, bytes flipped,
overwritten, inserted or deleted, header fields changed (counts, sizes, types, field names,
declared point counts), values made NaN, infinite, huge or negative, JSON/YAML values of the
wrong type, unicode; and plain random bytes. Each example asserts that the reader either returns
a valid result or raises :class:`~nbcalib.errors.InputError` whose message is one line naming the
file (:func:`_read_or_refuse`).

The example counts keep the whole file well under a minute on two cores. Under CI (``CI`` set)
the examples are derandomized, so that a run is repeatable; ``NBCALIB_FUZZ_SCALE=20`` runs twenty
times as many examples, for a deeper search by hand. The last section holds regular tests of the
findings of the user test of issue 17.
"""

from __future__ import annotations

import io
import json
import logging
import os
import re
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from nbcalib.camera import CameraModel, create_camera
from nbcalib.errors import InputError
from nbcalib.io.calib_json import read_calib_json
from nbcalib.io.camera_file import load_camera
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.io.image import read_image
from nbcalib.io.pcd import write_pcd
from nbcalib.io.pointcloud import POINTCLOUD_SUFFIXES, PointCloud, read_pointcloud

DATA = Path(__file__).parent / "data"
_SCALE = max(1, int(os.environ.get("NBCALIB_FUZZ_SCALE", "1")))


def fuzz(examples: int) -> settings:
    """Hypothesis settings of a fuzz test: ``examples`` (times the scale), no deadline."""
    return settings(
        max_examples=examples * _SCALE,
        deadline=None,
        derandomize=bool(os.environ.get("CI")),
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    """One folder for the module; each example writes its files into a fresh subfolder."""
    return tmp_path_factory.mktemp("fuzz")


def _fresh(scratch: Path) -> Path:
    return Path(tempfile.mkdtemp(dir=scratch))


def _read_or_refuse(read, path, *names: str):
    """``read(path)``; an InputError must be one line naming the file (then None is returned).

    ``names``: what the message may name instead of the file's name (a bag and topic, or
    another file the reader reads).
    """
    names = names or (Path(path).name,)
    try:
        result = read(path)
    except InputError as exc:
        message = str(exc)
        assert "\n" not in message and "\r" not in message, message
        assert any(name in message for name in names), f"{names} not named in: {message}"
        event("refused")
        return None
    event("read")
    return result


def _check_cloud(cloud: PointCloud) -> None:
    n = len(cloud)
    assert cloud.points.shape == (n, 3) and cloud.points.dtype == np.float64
    assert np.isfinite(cloud.points).all()
    for values in (cloud.intensity, cloud.times):
        assert values is None or values.shape == (n,)
    assert all(len(values) == n for values in cloud.fields.values())


# ------------------------------------------------------------------------------ mutations

#: Replacement header words: counts, sizes, types, names, numbers of every kind, unicode.
_WORDS = (
    "0 1 -1 2 3 4 8 -7 65536 4294967296 99999999999999999999 1e308 nan inf -inf 0.5 x y _ _pad0 "
    "intensity F I U ascii binary binary_compressed float uchar double list vertex face"
)
TOKENS = st.sampled_from([*_WORDS.split(), "\u00e9t\u00e9", "\u2603", ""])


EDITS = ("truncate", "flip", "overwrite", "insert", "delete")


@st.composite
def mutated_bytes(draw, data: bytes, start: int = 0, edits=EDITS) -> bytes:
    """1 to 3 edits of ``data`` at or after ``start``: truncate, flip, overwrite, insert, delete.

    Positions are uniform, or (as Hypothesis draws integers) mostly near ``start``: the header.
    """
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        lo, hi = min(start, len(out)), len(out)
        pos = draw(
            st.integers(lo, hi) | st.randoms().map(lambda r, lo=lo, hi=hi: r.randint(lo, hi))
        )
        kind = draw(st.sampled_from(edits))
        if kind == "truncate":
            del out[pos:]
        elif kind == "flip" and pos < len(out):
            out[pos] ^= 1 << draw(st.integers(0, 7))
        elif kind == "overwrite":
            chunk = draw(st.binary(min_size=1, max_size=8))
            out[pos : pos + len(chunk)] = chunk
        elif kind == "insert":
            out[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        else:
            del out[pos : pos + draw(st.integers(1, 16))]
    return bytes(out)


@st.composite
def mutated_lines(draw, text: str) -> str:
    """One edit of a line-based header: a word or all values replaced, a line dropped or doubled."""
    lines = text.split("\n")
    i = draw(st.integers(0, len(lines) - 1))
    words = lines[i].split(" ")
    kind = draw(st.sampled_from(("word", "values", "drop", "double")))
    if kind == "word":
        words[draw(st.integers(0, len(words) - 1))] = draw(TOKENS)
        lines[i] = " ".join(words)
    elif kind == "values":
        lines[i] = " ".join(words[:1] + draw(st.lists(TOKENS, max_size=5)))
    elif kind == "drop":
        del lines[i]
    else:
        lines.insert(i, lines[i])
    return "\n".join(lines)


@st.composite
def mutated_file(draw, data: bytes, header_end: int) -> bytes:
    """The file as is, its text header edited, its data edited, or both (``header_end``: split)."""
    header, body = data[:header_end], data[header_end:]
    kind = draw(st.sampled_from(("none", "header", "body", "both")))
    if kind in ("header", "both"):
        header = draw(mutated_lines(header.decode("ascii"))).encode("utf-8")
    if kind in ("body", "both"):
        body = draw(mutated_bytes(body))
    return header + body


def _numbers(dtype, shape) -> st.SearchStrategy[np.ndarray]:
    """Arrays of any value of ``dtype``: NaN, infinities, huge, negative, subnormal."""
    return hnp.arrays(np.dtype(dtype), shape)


# ------------------------------------------------------------------------------ PCD

_PCD_DTYPES = ("f4", "f8", "i1", "u1", "i2", "u2", "i4", "u4", "i8", "u8")
_EXTRA_FIELDS = ("intensity", "reflectivity", "t", "timestamp", "ring", "_")


@st.composite
def pcd_files(draw, scratch: Path) -> bytes:
    """A PCD file of 0 to 6 points (any encoding, field types and counts), then mutated."""
    n = draw(st.integers(0, 6))
    xyz_type = draw(st.sampled_from(("f4", "f8", "i2")))
    fields = {c: draw(_numbers(xyz_type, n)) for c in "xyz"}
    for name in draw(st.lists(st.sampled_from(_EXTRA_FIELDS), max_size=2, unique=True)):
        count = draw(st.integers(1, 3))
        shape = (n, count) if count > 1 else n
        key = "pad_" if name == "_" else name  # a "_" column: renamed in the header below
        fields[key] = draw(_numbers(draw(st.sampled_from(_PCD_DTYPES)), shape))
    encoding = draw(st.sampled_from(("ascii", "binary", "binary_compressed")))
    path = _fresh(scratch) / "valid.pcd"
    write_pcd(path, fields, encoding=encoding)
    data = path.read_bytes().replace(b" pad_", b" _")
    return draw(mutated_file(data, data.index(b"\nDATA ") + 1))


@fuzz(150)
@given(data=st.data())
def test_fuzz_pcd(scratch, data):
    if data.draw(st.booleans()):
        content = data.draw(pcd_files(scratch))
    else:  # random bytes behind a plausible header line
        content = data.draw(st.sampled_from([b"", b"# .PCD v0.7\n", b"FIELDS x y z\n"]))
        content += data.draw(st.binary(max_size=200))
    path = _fresh(scratch) / "cloud.pcd"
    path.write_bytes(content)
    cloud = _read_or_refuse(read_pointcloud, path)
    if cloud is not None:
        _check_cloud(cloud)


# ------------------------------------------------------------------------------ PLY

_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4"}
_PLY_TYPES |= {"uint": "u4", "float": "f4", "double": "f8", "float32": "f4", "uint8": "u1"}
_PLY_FORMATS = {"ascii": "<", "binary_little_endian": "<", "binary_big_endian": ">"}


def _ply_rows(table: np.ndarray, ascii: bool, order: str) -> bytes:
    if not ascii:
        return table.astype(table.dtype.newbyteorder(order)).tobytes()
    lines = [" ".join(repr(v.item()) for v in row) for row in table]
    return "".join(line + "\n" for line in lines).encode("ascii")


@st.composite
def ply_files(draw) -> bytes:
    """A PLY file: an optional element before the vertices, x y z and more, faces after."""
    fmt = draw(st.sampled_from(sorted(_PLY_FORMATS)))
    ascii, order = fmt == "ascii", _PLY_FORMATS[fmt]
    n = draw(st.integers(0, 5))
    props = [(c, draw(st.sampled_from(("float", "double", "short")))) for c in "xyz"]
    for name in draw(
        st.lists(st.sampled_from(("intensity", "t", "ring")), max_size=2, unique=True)
    ):
        props.append((name, draw(st.sampled_from(sorted(_PLY_TYPES)))))
    header = [f"ply\nformat {fmt} 1.0\ncomment made by the fuzzer\n"]
    body = []
    if draw(st.booleans()):  # an element before the vertices (skipped by the reader)
        header.append("element camera 1\nproperty float view_px\nproperty uchar flag\n")
        camera = np.zeros(1, dtype=[("view_px", "f4"), ("flag", "u1")])
        body.append(_ply_rows(camera, ascii, order))
    header.append(f"element vertex {n}\n")
    header += [f"property {typ} {name}\n" for name, typ in props]
    dtype = np.dtype([(name, _PLY_TYPES[typ]) for name, typ in props])
    vertices = np.zeros(n, dtype=dtype)
    for name in dtype.names:
        vertices[name] = draw(_numbers(dtype[name], n))
    body.append(_ply_rows(vertices, ascii, order))
    if draw(st.booleans()):  # faces after the vertices (ignored)
        header.append("element face 1\nproperty list uchar int vertex_indices\n")
        body.append(b"3 0 1 2\n" if ascii else b"\x03" + np.arange(3, dtype=order + "i4").tobytes())
    head = "".join(header) + "end_header\n"
    return draw(mutated_file(head.encode("ascii") + b"".join(body), len(head)))


@fuzz(150)
@given(data=st.data())
def test_fuzz_ply(scratch, data):
    if data.draw(st.booleans()):
        content = data.draw(ply_files())
    else:
        content = data.draw(st.sampled_from([b"", b"ply\n", b"ply\nformat ascii 1.0\n"]))
        content += data.draw(st.binary(max_size=100)) + data.draw(
            st.sampled_from([b"", b"end_header\n"])
        )
    path = _fresh(scratch) / "mesh.ply"
    path.write_bytes(content)
    cloud = _read_or_refuse(read_pointcloud, path)
    if cloud is not None:
        _check_cloud(cloud)


# ------------------------------------------------------------------------------ KITTI .bin


@fuzz(60)
@given(data=st.data())
def test_fuzz_kitti_bin(scratch, data):
    records = data.draw(_numbers("<f4", (data.draw(st.integers(0, 6)), 4)))
    content = records.tobytes()
    if data.draw(st.booleans()):
        content = data.draw(mutated_bytes(content))
    path = _fresh(scratch) / "000000.bin"
    path.write_bytes(content)
    cloud = _read_or_refuse(read_pointcloud, path)
    if cloud is not None:
        _check_cloud(cloud)


# ------------------------------------------------------------------------------ NumPy files


#: dtypes a point cloud may have (mostly), and others
_NUMERIC = st.sampled_from(("<f4", ">f8", "<i2", "u1", "<u8"))
_ANY_DTYPE = _NUMERIC | st.sampled_from(("?", "<c8", "<M8[s]", "<U3", "S2"))


def _arrays(n: int) -> st.SearchStrategy[np.ndarray]:
    """Arrays an .npy may hold: mostly (N, 3) / (N, 4) numbers or x, y, z records; or not."""
    matrices = hnp.arrays(_NUMERIC, st.sampled_from([(n, 3), (n, 4)]))
    others = hnp.arrays(_ANY_DTYPE, st.sampled_from([(n, 2), (n,), (), (n, 3, 1), (3, n), (n, 4)]))
    extras = st.lists(
        st.tuples(st.sampled_from(("intensity", "t", "ring", "x")), _ANY_DTYPE), max_size=3
    )
    records = st.tuples(st.permutations([("x", "<f4"), ("y", "<f8"), ("z", "<i2")]), extras).map(
        lambda parts: np.dtype(
            list({name: (name, t) for name, t in [*parts[0], *parts[1]]}.values())
        )
    )
    return st.one_of(
        matrices, others, hnp.arrays(records, st.sampled_from([(n,), (n,), (), (1, n)]))
    )


@st.composite
def npy_files(draw) -> bytes:
    """An .npy of :func:`_arrays`, as is, a word of its header replaced, or its bytes edited."""
    array = draw(_arrays(draw(st.integers(0, 5))))
    stream = io.BytesIO()
    np.save(stream, np.asfortranarray(array) if draw(st.booleans()) else array)
    content = stream.getvalue()
    header_end = content.index(b"\n") + 1
    kind = draw(st.sampled_from(("none", "header", "body")))
    if kind == "header":  # the header is a Python dict literal: edit its words
        header = content[:header_end].decode("latin-1")
        words = header.replace(",", " , ").replace(":", " : ").split(" ")
        replacements = "'<f4' '|O' '<U0' True ( ) (-1, (99999999999, {} 'shape' '' 3)".split()
        words[draw(st.integers(0, len(words) - 1))] = draw(st.sampled_from(replacements))
        size = header_end - 1  # the length the file declares: kept, so the edit is parsed
        edited = " ".join(words).rstrip("\n").ljust(size)[:size] + "\n"
        return edited.encode("latin-1") + content[header_end:]
    if kind == "body":
        return draw(mutated_bytes(content, start=draw(st.sampled_from([0, 8, header_end]))))
    return content


@fuzz(120)
@given(data=st.data())
def test_fuzz_npy(scratch, data):
    content = data.draw(
        st.one_of(npy_files(), st.binary(max_size=64), st.text(max_size=40).map(str.encode))
    )
    path = _fresh(scratch) / "scan.npy"
    path.write_bytes(content)
    cloud = _read_or_refuse(read_pointcloud, path)
    if cloud is not None:
        _check_cloud(cloud)


@st.composite
def npz_files(draw) -> bytes:
    """An .npz of ``points`` or ``x, y, z`` arrays and more (lengths mostly equal), mutated."""
    n = draw(st.integers(0, 4))
    layout = draw(st.sampled_from([("points",), ("x", "y", "z"), ()]))
    extras = st.sampled_from(("intensity", "t", "other", "x", "points"))
    arrays = {}
    for name in (*layout, *draw(st.lists(extras, max_size=2))):
        length = n if draw(st.integers(0, 5)) else n + 1
        if name == "points":
            arrays[name] = draw(_arrays(length))
        else:
            dtype = _NUMERIC if draw(st.integers(0, 3)) else _ANY_DTYPE
            arrays[name] = draw(hnp.arrays(dtype, st.sampled_from([(length,), (length, 2)])))
    stream = io.BytesIO()
    (np.savez_compressed if draw(st.booleans()) else np.savez)(stream, **arrays)
    content = stream.getvalue()
    return draw(mutated_bytes(content)) if draw(st.integers(0, 2)) == 0 else content


@fuzz(100)
@given(data=st.data())
def test_fuzz_npz(scratch, data):
    if data.draw(st.integers(0, 3)):
        content = data.draw(npz_files())
    else:
        content = b"PK\x03\x04" + data.draw(st.binary(max_size=64))
    path = _fresh(scratch) / "scan.npz"
    path.write_bytes(content)
    cloud = _read_or_refuse(read_pointcloud, path)
    if cloud is not None:
        _check_cloud(cloud)


# ------------------------------------------------------------------------------ dispatcher


@fuzz(60)
@given(data=st.data())
def test_fuzz_pointcloud_dispatch(scratch, data):
    """Any content under any point cloud suffix (one format's file under another's name)."""
    content = data.draw(
        st.one_of(pcd_files(scratch), ply_files(), npy_files(), npz_files(), st.binary(max_size=64))
    )
    suffix = data.draw(st.sampled_from([*POINTCLOUD_SUFFIXES, ".PCD", ".xyz", ""]))
    folder = _fresh(scratch)
    path = folder / f"scan{suffix}"
    kind = data.draw(st.sampled_from(("file", "folder", "missing")))
    if kind == "file":
        path.write_bytes(content)
    elif kind == "folder":
        path.mkdir()
    cloud = _read_or_refuse(read_pointcloud, path)
    if cloud is not None:
        _check_cloud(cloud)


# ------------------------------------------------------------------------------ bags

BAG_FORMATS = {"bag1": "rec.bag", "bag2": "rec_db3", "mcap": "rec_mcap"}


@pytest.fixture(scope="module")
def valid_bags(tmp_path_factory) -> dict[str, dict[str, bytes]]:
    """Small valid bags of every format (nbcalib's writer): format -> {relative path: bytes}."""
    pytest.importorskip("rosbags")
    from nbcalib.io.bag_writer import BagWriter

    rng = np.random.default_rng(7)
    root = tmp_path_factory.mktemp("bags")
    cloud = {c: rng.normal(size=4).astype(np.float32) for c in "xyz"}
    cloud["intensity"] = np.arange(4, dtype=np.float32)
    cloud["t"] = np.array([0.0, 0.01, 0.02, np.nan], np.float32)
    cloud["x"][1] = np.nan
    livox = {"x": cloud["y"], "y": cloud["z"], "z": cloud["y"], "reflectivity": np.arange(4)}
    livox["offset_time"] = np.arange(4) * 1000
    camera = create_camera("plumb_bob", [50, 52, 16, 12], [0.1, -0.05, 0.001, 0.002, 0.01], 32, 24)
    bags = {}
    for fmt, name in BAG_FORMATS.items():
        with BagWriter(root / name, fmt) as bag:
            bag.write_tf_static(10, "camera", "lidar", np.eye(4))
            empty_tf = bag._msg("tf2_msgs/msg/TFMessage", transforms=[])  # 4 bytes, no header
            bag._write("/tf_static", "tf2_msgs/msg/TFMessage", 11, empty_tf)
            bag.write_pointcloud("/points", 10, cloud, "lidar")
            bag.write_livox("/livox", 10, livox, "lidar")
            bag.write_image("/mono", 10, rng.integers(0, 256, (3, 4), dtype=np.uint8), "camera")
            bag.write_image("/rgb", 10, rng.integers(0, 256, (3, 4, 3), dtype=np.uint8), "camera")
            bag.write_compressed_image("/png", 10, np.zeros((3, 4), np.uint8), "camera")
            bag.write_camera_info("/info", 10, camera, "camera")
        files = [root / name] if fmt == "bag1" else sorted((root / name).iterdir())
        bags[fmt] = {str(f.relative_to(root)): f.read_bytes() for f in files}
    return _Quiet(bags)


class _Quiet(dict):
    """A dict that Hypothesis prints short in a failure report."""

    def __repr__(self) -> str:
        return f"<{', '.join(self)}>"


def _read_bag(path: Path) -> None:
    """Every message of every topic, decoded by the reader of its kind and checked."""
    from nbcalib.io.bag import MESSAGE_KINDS, open_bag

    with open_bag(path) as bag:
        for topic, msgtype in bag.topics.items():
            kind = next((k for k, types in MESSAGE_KINDS.items() if msgtype in types), None)
            bag.stamps(topic)
            if kind == "point cloud":
                for _, cloud in bag.pointclouds(topic):
                    _check_cloud(cloud)
            elif kind == "image":
                for _, image in bag.images(topic):
                    assert image.ndim in (2, 3) and image.dtype in (np.uint8, np.uint16)
            elif kind == "camera info":
                assert isinstance(bag.camera_info(topic), CameraModel)
            elif kind == "tf":
                for *_, T in bag.tf_static(topic):
                    assert T.shape == (4, 4) and np.isfinite(T).all()


#: little-endian float64 1.0 or 0.5 (quaternions, camera matrices), uint32 1..8 (sizes, counts)
_FLOAT_SPOTS = re.compile(b"|".join(re.escape(np.float64(v).tobytes()) for v in (1.0, 0.5)))
_COUNT_SPOTS = re.compile(rb"[\x01-\x08]\x00\x00\x00")
ODD_FLOATS = st.sampled_from([0.0, -1.0, 1e308, -1e308, 5e-324, np.nan, np.inf, -np.inf])
ODD_COUNTS = st.sampled_from([0, 3, 2**31 - 1, 2**32 - 1])


@st.composite
def mutated_values(draw, data: bytes) -> bytes:
    """1 to 3 values in ``data`` made odd: a float64 1.0 or 0.5, or a uint32 count 1..8."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        floats = draw(st.booleans())
        spots = [m.start() for m in (_FLOAT_SPOTS if floats else _COUNT_SPOTS).finditer(out)]
        if spots:
            k = draw(st.sampled_from(spots))
            value = np.float64(draw(ODD_FLOATS)) if floats else np.uint32(draw(ODD_COUNTS))
            out[k : k + value.itemsize] = value.tobytes()
    return bytes(out)


@fuzz(40)
@pytest.mark.parametrize("fmt", sorted(BAG_FORMATS))
@given(data=st.data())
def test_fuzz_bag(scratch, valid_bags, fmt, data):
    folder = _fresh(scratch)
    files = valid_bags[fmt]
    victim = data.draw(st.sampled_from(sorted(files)))
    for name, content in files.items():
        if name == victim:
            if name.endswith(".yaml") and data.draw(st.booleans()):
                content = data.draw(mutated_lines(content.decode())).encode()
            elif data.draw(st.booleans()):
                content = data.draw(mutated_values(content))
            else:  # mostly edits in place: shifted offsets are refused when the bag opens
                edits = data.draw(st.sampled_from([("flip", "overwrite")] * 3 + [EDITS]))
                content = data.draw(mutated_bytes(content, edits=edits))
        (folder / name).parent.mkdir(exist_ok=True)
        (folder / name).write_bytes(content)
    path = folder / BAG_FORMATS[fmt]
    _read_or_refuse(_read_bag, path)


# ------------------------------------------------------------------------------ bag messages

SOURCE = "rec.bag /topic"  # what a bag's reader passes as the source of a message
_COUNTS = st.one_of(st.integers(0, 8), st.sampled_from([2**31 - 1, 2**32 - 1]))


def _sizes(draw, consistent: bool) -> tuple[int, int]:
    """(height, width): small for a consistent message, else any count."""
    counts = st.integers(1, 6) if consistent else _COUNTS
    return draw(counts), draw(counts)


@st.composite
def image_messages(draw) -> SimpleNamespace:
    """sensor_msgs/Image stand-ins: consistent ones of every encoding, or any header and data."""
    from nbcalib.io.bag_messages import _IMAGE_LAYOUTS

    consistent = draw(st.booleans())
    encodings = st.sampled_from(sorted(_IMAGE_LAYOUTS))
    encoding = draw(encodings if consistent else encodings | st.text(max_size=8))
    height, width = _sizes(draw, consistent)
    channels, dtype, _ = _IMAGE_LAYOUTS.get(encoding.lower(), (1, np.uint8, ""))
    row = width * channels * np.dtype(dtype).itemsize
    step = draw(st.sampled_from([row, row + 3, 0]) if consistent else _COUNTS)
    size = min(height * max(step, row), 4096) + (0 if consistent else draw(st.integers(-3, 3)))
    return SimpleNamespace(
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=draw(st.integers(0, 1)),
        step=step,
        data=draw(st.binary(min_size=max(size, 0), max_size=max(size, 0))),
    )


@fuzz(150)
@given(msg=image_messages(), grey=st.booleans())
def test_fuzz_image_message(msg, grey):
    from nbcalib.io.bag_messages import decode_image

    image = _read_or_refuse(lambda m: decode_image(m, grey=grey, source=SOURCE), msg, SOURCE)
    if image is not None:
        assert image.shape[:2] == (msg.height, msg.width)


#: bytes of the PointField datatypes 1..8 (INT8 ... FLOAT64)
POINTFIELD_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8}


@st.composite
def pointcloud2_messages(draw) -> SimpleNamespace:
    """sensor_msgs/PointCloud2 stand-ins: x, y, z and more packed, or any fields and steps."""
    consistent = draw(st.booleans())
    if consistent:
        layout = [("x", 7, 1), ("y", 7, 1), ("z", 8, 1)]
        layout += draw(st.lists(st.sampled_from([("intensity", 2, 1), ("t", 6, 1), ("v", 3, 2)])))
        fields, offset = [], 0
        for name, datatype, count in layout:
            fields.append(SimpleNamespace(name=name, offset=offset, datatype=datatype, count=count))
            offset += POINTFIELD_SIZES[datatype] * count
        point_step = offset + draw(st.integers(0, 3))
    else:
        fields = draw(
            st.lists(
                st.builds(
                    SimpleNamespace,
                    name=st.sampled_from(["x", "y", "z", "intensity", "t", "", "x"]),
                    offset=st.one_of(st.integers(0, 16), _COUNTS),
                    datatype=st.integers(0, 9),
                    count=st.integers(0, 3),
                ),
                max_size=5,
            )
        )
        point_step = draw(st.one_of(st.integers(0, 24), _COUNTS))
    height, width = _sizes(draw, consistent)
    row_step = draw(st.sampled_from([width * point_step, width * point_step + 2]) | _COUNTS)
    size = min(height * max(row_step, 0), 2048) + draw(st.sampled_from([0, 0, -1, 3]))
    return SimpleNamespace(
        height=height,
        width=width,
        fields=fields,
        is_bigendian=draw(st.booleans()),
        point_step=point_step,
        row_step=row_step,
        data=draw(hnp.arrays(np.uint8, max(size, 0))),
    )


@fuzz(150)
@given(msg=pointcloud2_messages())
def test_fuzz_pointcloud2_message(msg):
    from nbcalib.io.pointcloud2 import pointcloud2_to_pointcloud

    cloud = _read_or_refuse(lambda m: pointcloud2_to_pointcloud(m, source=SOURCE), msg, SOURCE)
    if cloud is not None:
        _check_cloud(cloud)


_ANY_NUMBER = st.one_of(
    st.floats(), st.integers(-(2**31), 2**31), st.sampled_from([0.0, 1.0, 1e308, -1e308])
)


#: ROS and nbcalib distortion model names, and the length of their D
CAMERA_INFO_MODELS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4, "atan": 1}
CAMERA_INFO_MODELS |= {"omnidir": 5, "equirectangular": 0, "pinhole": 0, "": 0, "unknown": 2}


@fuzz(100)
@given(
    width=_COUNTS,
    height=_COUNTS,
    model=st.sampled_from(sorted(CAMERA_INFO_MODELS)),
    d=st.lists(_ANY_NUMBER, max_size=9) | st.lists(st.floats(-0.1, 0.1), min_size=8, max_size=8),
    k=st.lists(_ANY_NUMBER, max_size=10) | st.lists(st.floats(1, 900), min_size=4, max_size=4),
)
def test_fuzz_camera_info_message(width, height, model, d, k):
    from nbcalib.io.bag_messages import camera_from_camera_info_msg

    if len(k) == 4:  # fx, fy, cx, cy: a plausible K, and D of the model's length
        k, d = [k[0], 0, k[2], 0, k[1], k[3], 0, 0, 1], d[: CAMERA_INFO_MODELS[model]]
    msg = SimpleNamespace(width=width, height=height, distortion_model=model, d=d, k=k)
    camera = _read_or_refuse(lambda m: camera_from_camera_info_msg(m, source=SOURCE), msg, SOURCE)
    assert camera is None or isinstance(camera, CameraModel)


# ------------------------------------------------------------------------------ camera files

#: Values of the wrong type or range for any entry of a YAML/JSON file.
ODD_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.sampled_from([0, -1, 10**400, 1e308, -0.0, float("nan"), float("inf"), [[1, 2], [3]]]),
    st.floats(),
    st.text(max_size=5),
    st.lists(st.one_of(st.floats(), st.integers(-5, 5)), max_size=10),
    st.dictionaries(
        st.sampled_from(["data", "rows", "camera_model", "x"]), st.integers(), max_size=2
    ),
)


def _paths(tree, prefix=()):
    """Every key path into nested dicts and lists (the root included)."""
    yield prefix
    if isinstance(tree, dict):
        items = tree.items()
    elif isinstance(tree, list):
        items = enumerate(tree)
    else:
        items = ()
    for key, value in items:
        yield from _paths(value, (*prefix, key))


@st.composite
def mutated_tree(draw, tree):
    """One entry of a parsed file replaced by an odd value, deleted, or renamed (a copy)."""
    tree = json.loads(json.dumps(tree))
    path = draw(st.sampled_from(list(_paths(tree))))
    if not path:
        return draw(ODD_VALUES)
    parent = tree
    for key in path[:-1]:
        parent = parent[key]
    kind = draw(st.sampled_from(("replace", "replace", "delete", "rename")))
    if kind == "replace":
        parent[path[-1]] = draw(ODD_VALUES)
    elif kind == "delete":
        del parent[path[-1]]
    elif isinstance(parent, dict):
        name = draw(st.sampled_from(["K", "D", "width", "\u00e9", "intrinsics"]))
        parent[name] = parent.pop(path[-1])
    return tree


def _camera_sources() -> dict[str, str]:
    """Valid camera files: file name -> text (every format load_camera reads)."""
    sources = {
        name: (DATA / name).read_text()
        for name in ("camera_info_ros.yaml", "camera_nbcalib.yaml", "camera_opencv.yaml")
    }
    sources["calib.json"] = (DATA / "reference_calib.json").read_text()
    sources["camera.json"] = json.dumps(
        {"camera_model": "atan", "width": 640, "height": 480, "intrinsics": [400, 400, 320, 240]}
        | {"distortion_coeffs": [0.9]}
    )
    sources["camera_info.yaml"] = yaml.safe_dump(
        {"width": 640, "height": 480, "distortion_model": "equidistant", "D": [0.1, 0, 0, 0]}
        | {"K": [400.0, 0, 320, 0, 400, 240, 0, 0, 1]}
    )
    sources["opencv.xml"] = (
        '<?xml version="1.0"?>\n<opencv_storage>\n<image_width>640</image_width>\n'
        '<image_height>480</image_height>\n<camera_matrix type_id="opencv-matrix">\n'
        "  <rows>3</rows><cols>3</cols><dt>d</dt>\n"
        "  <data>400. 0. 320. 0. 400. 240. 0. 0. 1.</data>\n</camera_matrix>\n</opencv_storage>\n"
    )
    return sources


CAMERA_SOURCES = _camera_sources()


@st.composite
def camera_files(draw) -> tuple[str, bytes]:
    """(file name, content): a valid camera file, its parsed tree edited, or its bytes edited."""
    name = draw(st.sampled_from(sorted(CAMERA_SOURCES)))
    text = CAMERA_SOURCES[name]
    kind = draw(st.sampled_from(("none", "tree", "tree", "bytes", "random")))
    parseable = not text.startswith(("%YAML", "<?xml"))
    if kind == "tree" and parseable:
        tree = draw(mutated_tree(yaml.safe_load(text)))
        if name.endswith(".json"):
            return name, json.dumps(tree).encode()
        return name, yaml.safe_dump(tree, allow_unicode=True).encode()
    if kind in ("bytes", "tree"):
        return name, draw(mutated_bytes(text.encode()))
    if kind == "random":
        return name, draw(st.one_of(st.binary(max_size=64), st.text(max_size=40).map(str.encode)))
    return name, text.encode()


@fuzz(200)
@given(file=camera_files(), size=st.sampled_from([None, (640, 480), (1280, 720), (0, 0)]))
def test_fuzz_camera_file(scratch, file, size):
    name, content = file
    path = _fresh(scratch) / name
    path.write_bytes(content)
    kwargs = {} if size is None else {"width": size[0], "height": size[1]}
    camera = _read_or_refuse(lambda p: load_camera(p, **kwargs), path)
    assert camera is None or isinstance(camera, CameraModel)


# ------------------------------------------------------------------------------ calib.json


#: the camera image of the first bag of reference_calib.json, read for the image size
WORKDIR_IMAGE = "rosbag2_2023_03_09-13_42_46.png"


@fuzz(150)
@given(data=st.data())
def test_fuzz_calib_json(scratch, data):
    from nbcalib.io.calib_json import STAGES

    text = CAMERA_SOURCES["calib.json"]
    kind = data.draw(st.sampled_from(("tree", "tree", "bytes", "random")))
    if kind == "tree":
        tree = json.loads(text)
        for _ in range(data.draw(st.integers(1, 2))):
            tree = data.draw(mutated_tree(tree))
        content = json.dumps(tree).encode()  # NaN and Infinity too (allow_nan)
    elif kind == "bytes":
        content = data.draw(mutated_bytes(text.encode()))
    else:
        content = data.draw(st.binary(max_size=64))
    folder = _fresh(scratch)
    path = folder / "calib.json"
    path.write_bytes(content)
    if data.draw(st.booleans()):  # the work directory's camera image, read for its size
        png = _encoded(".png", np.zeros((4, 6), np.uint8))
        (folder / WORKDIR_IMAGE).write_bytes(data.draw(st.just(png) | mutated_bytes(png)))
    calib = _read_or_refuse(read_calib_json, path)
    _read_or_refuse(read_ground_truth, path)
    if calib is None:
        return
    size = data.draw(st.sampled_from([None, (640, 480)]))
    uses = [
        lambda _: calib.camera_model(*(size or ())),
        lambda _: calib.bag_names,
        lambda _: calib.latest_stage(),
        *[
            lambda _, s=stage: calib.get_T_camera_lidar(s)
            for stage in STAGES
            if calib.has_result(stage)
        ],
    ]
    for use in uses:
        result = _read_or_refuse(use, path, path.name, WORKDIR_IMAGE)
        if isinstance(result, np.ndarray):
            assert result.shape == (4, 4) and np.isfinite(result).all()


# ------------------------------------------------------------------------------ images


def _encoded(suffix: str, image: np.ndarray) -> bytes:
    import cv2

    ok, encoded = cv2.imencode(suffix, image)
    assert ok, (suffix, image.shape, image.dtype)
    return encoded.tobytes()


#: suffix -> (dtypes, channel counts) that OpenCV writes in that format
IMAGE_FORMATS = {
    ".png": ((np.uint8, np.uint16), (1, 3, 4)),
    ".jpg": ((np.uint8,), (1, 3)),
    ".bmp": ((np.uint8,), (1, 3, 4)),
    ".tiff": ((np.uint8, np.uint16), (1, 3, 4)),
    ".webp": ((np.uint8,), (3, 4)),
    ".pgm": ((np.uint8, np.uint16), (1,)),
    ".ppm": ((np.uint8, np.uint16), (3,)),
}


@st.composite
def image_files(draw) -> tuple[str, bytes]:
    """(suffix, content): a small image in any format OpenCV writes, then perhaps mutated."""
    suffix = draw(st.sampled_from(sorted(IMAGE_FORMATS)))
    dtypes, channel_counts = IMAGE_FORMATS[suffix]
    dtype, channels = draw(st.sampled_from(dtypes)), draw(st.sampled_from(channel_counts))
    shape = (draw(st.integers(1, 6)), draw(st.integers(1, 6)))
    image = draw(hnp.arrays(dtype, shape + ((channels,) if channels > 1 else ())))
    content = _encoded(suffix, image)
    if draw(st.booleans()):
        content = draw(mutated_bytes(content))
    return suffix, content


@fuzz(200)
@given(file=image_files() | st.tuples(st.just(".png"), st.binary(max_size=64)), grey=st.booleans())
def test_fuzz_image_file(scratch, file, grey):
    suffix, content = file
    path = _fresh(scratch) / f"camera{suffix}"
    path.write_bytes(content)
    image = _read_or_refuse(lambda p: read_image(p, grey=grey), path)
    if image is not None:
        assert image.dtype in (np.uint8, np.uint16)
        assert image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3 and not grey)


# ------------------------------------------------------------------------------ user test findings
# Issue 17: three messages of the user test, now plain and naming the file.


def test_a_text_file_named_npy_is_not_a_numpy_file(tmp_path):
    path = tmp_path / "points.npy"
    path.write_text("x y z\n1 2 3\n")
    with pytest.raises(InputError, match=r"points\.npy: .* is not a NumPy file$") as info:
        read_pointcloud(path)
    assert "pickle" not in str(info.value)
    path = tmp_path / "points.npz"
    path.write_text("x y z\n1 2 3\n")
    with pytest.raises(InputError, match=r"points\.npz: .* is not a zip archive$"):
        read_pointcloud(path)


def _write_cloud(path: Path, xyzi: np.ndarray) -> None:
    """(N, 4) float32 x, y, z, intensity in the format of ``path``'s suffix."""
    from nbcalib.io.kitti_bin import write_kitti_bin
    from nbcalib.io.ply import write_ply

    fields = {name: xyzi[:, k] for k, name in enumerate(("x", "y", "z", "intensity"))}
    writers = {
        ".npy": lambda: np.save(path, xyzi),
        ".npz": lambda: np.savez(path, **fields),
        ".pcd": lambda: write_pcd(path, fields, encoding="binary_compressed"),
        ".ply": lambda: write_ply(path, xyzi[:, :3], xyzi[:, 3]),
        ".bin": lambda: write_kitti_bin(path, xyzi[:, :3], xyzi[:, 3]),
    }
    writers[path.suffix]()


@pytest.mark.parametrize("suffix", [".npy", ".npz", ".pcd", ".ply", ".bin"])
def test_non_finite_points_are_dropped_with_a_warning(tmp_path, caplog, suffix):
    xyzi = np.arange(36, dtype=np.float32).reshape(9, 4)
    xyzi[0::3, 0] = np.nan  # two thirds of the rows lose x, y or z
    xyzi[1::3, 2] = -np.inf
    path = tmp_path / f"scan{suffix}"
    _write_cloud(path, xyzi)
    with caplog.at_level(logging.WARNING, logger="nbcalib"):
        cloud = read_pointcloud(path)
    assert np.array_equal(cloud.points, xyzi[2::3, :3])
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [f"{path}: dropped 6 of 9 points with a non-finite x, y or z"]

    xyzi[2::3, 1] = np.nan  # and now every row
    _write_cloud(path, xyzi)
    with pytest.raises(InputError, match="none of its 9 points has a finite x, y and z") as info:
        read_pointcloud(path)
    assert str(info.value).startswith(f"{path}: ")


def test_non_finite_points_of_a_bag_are_one_warning_naming_it(tmp_path, caplog):
    pytest.importorskip("rosbags")
    from nbcalib.io.bag import read_pointclouds
    from nbcalib.io.bag_writer import BagWriter

    path = tmp_path / "drive.bag"
    x = np.array([0.0, np.nan, 2.0, np.inf], np.float32)
    with BagWriter(path, "bag1") as bag:
        for stamp in (1, 2, 3):
            zero = np.zeros_like(x)
            bag.write_pointcloud("/points", stamp, {"x": x, "y": zero, "z": zero}, "lidar")
    with caplog.at_level(logging.WARNING, logger="nbcalib"):
        clouds = [cloud for _, cloud in read_pointclouds(path)]
    assert [len(cloud) for cloud in clouds] == [2, 2, 2]
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [f"{path} /points: dropped 6 of 12 points with a non-finite x, y or z"]


@pytest.mark.parametrize("suffix", [".pcd", ".npy"])
def test_a_cloud_of_no_points_is_refused_naming_the_file(tmp_path, suffix):
    from nbcalib.preprocess.config import PreprocessConfig
    from nbcalib.preprocess.inputs import gather_files

    good, empty = tmp_path / f"good{suffix}", tmp_path / f"zero{suffix}"
    _write_cloud(good, np.ones((5, 4), np.float32))
    _write_cloud(empty, np.zeros((0, 4), np.float32))
    image = tmp_path / "image.png"
    image.write_bytes(_encoded(".png", np.zeros((40, 50), np.uint8)))
    pair = gather_files([good], image, PreprocessConfig())
    assert [len(scan) for scan in pair.scans] == [5]
    with pytest.raises(InputError, match=rf"^{empty}: holds no points$"):
        gather_files([good, empty], image, PreprocessConfig())


def test_a_damaged_opencv_matrix_does_not_crash_the_process(tmp_path):
    """OpenCV's ``FileNode.mat()`` corrupts memory on ``cols: -3``: the reader must not call it.

    In a child process with glibc's heap checks on, so that the corruption aborts it at once.
    """
    import subprocess
    import sys

    path = tmp_path / "camera.yaml"
    path.write_text(
        "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
        "   rows: 3\n   cols: -3\n   dt: d\n   data: [400, 0, 320, 0, 400, 240, 0, 0, 1]\n"
    )
    code = (
        "import sys\nfrom nbcalib.io.camera_file import load_camera\n"
        "for _ in range(30):\n    camera = load_camera(sys.argv[1])\nprint(camera.model)\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, str(path)],
        capture_output=True,
        text=True,
        env={**os.environ, "MALLOC_CHECK_": "3"},
        timeout=120,
    )
    assert run.returncode == 0 and run.stdout == "pinhole\n", run.stderr[-2000:]
