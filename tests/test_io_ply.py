"""PLY files: the reference's binary header, round trips, big endian and ascii with faces, and
corrupt files."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.ply import write_ply
from nbcalib.io.pointcloud import read_pointcloud


def test_ply_binary_header_is_the_references(tmp_path, rng):
    points = rng.normal(size=(20, 3))
    intensity = rng.random(20)
    write_ply(tmp_path / "a.ply", points, intensity)
    data = (tmp_path / "a.ply").read_bytes()
    header = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 20\nproperty float x\n"
        b"property float y\nproperty float z\nproperty float intensity\nend_header\n"
    )
    assert data.startswith(header) and len(data) == len(header) + 20 * 16
    body = np.frombuffer(data[len(header) :], "<f4").reshape(20, 4)
    assert np.array_equal(body[:, :3], points.astype(np.float32))


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_ply_round_trip(tmp_path, rng, encoding):
    points = rng.normal(size=(300, 3)) * 20
    intensity = rng.random(300)
    write_ply(tmp_path / "a.ply", points, intensity, encoding=encoding)
    cloud = read_pointcloud(tmp_path / "a.ply")
    assert np.array_equal(cloud.points, points.astype(np.float32).astype(np.float64))
    assert np.array_equal(cloud.intensity, intensity.astype(np.float32).astype(np.float64))
    no_intensity = tmp_path / "b.ply"
    write_ply(no_intensity, points, encoding=encoding)
    assert read_pointcloud(no_intensity).intensity is None


def test_ply_big_endian_with_faces(tmp_path, rng):
    vertices = np.zeros(4, dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("reflectivity", "u1")])
    vertices["x"] = rng.normal(size=4)
    vertices["reflectivity"] = [1, 2, 3, 4]
    header = (
        b"ply\nformat binary_big_endian 1.0\ncomment made by hand\nelement vertex 4\n"
        b"property double x\nproperty double y\nproperty double z\nproperty uchar reflectivity\n"
        b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face = struct.pack(">Biii", 3, 0, 1, 2)
    (tmp_path / "be.ply").write_bytes(header + vertices.tobytes() + face)
    cloud = read_pointcloud(tmp_path / "be.ply")
    assert np.array_equal(cloud.points[:, 0], vertices["x"])
    assert np.array_equal(cloud.intensity, [1.0, 2.0, 3.0, 4.0])


def test_ply_ascii_with_faces(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    (tmp_path / "t.ply").write_text(text)
    assert np.array_equal(
        read_pointcloud(tmp_path / "t.ply").points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    )


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n" + bytes(12 * 4),
            "expected 10 vertices, file holds 4",
        ),
        (b"solid cube\nfacet normal 0 0 1\n", "not a PLY file"),
        (
            b"ply\nformat binary_little_endian 1.0\nelement face 1\nproperty int v\nend_header\n",
            "no 'vertex' element",
        ),
        (
            b"ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n",
            "unknown PLY format",
        ),
    ],
)
def test_corrupt_ply(tmp_path, content, problem):
    (tmp_path / "bad.ply").write_bytes(content)
    with pytest.raises(InputError, match=problem) as info:
        read_pointcloud(tmp_path / "bad.ply")
    assert "bad.ply" in str(info.value)


def test_the_work_directory_layout_is_read_as_one_block(tmp_path, rng):
    """x, y, z, intensity float32 (as nbcalib writes): one (N, 4) block, the fields' values."""
    from nbcalib.io.ply import read_ply_fields, read_ply_xyzi

    points, values = rng.normal(size=(300, 3)), rng.random(300)
    write_ply(tmp_path / "a.ply", points, values)
    block = read_ply_xyzi(tmp_path / "a.ply")
    fields = read_ply_fields(tmp_path / "a.ply")
    assert block.shape == (300, 4) and block.dtype == np.float32
    for k, name in enumerate(("x", "y", "z", "intensity")):
        assert np.array_equal(block[:, k], fields[name])
    # any other layout: None, for the general reader
    write_ply(tmp_path / "b.ply", points)  # no intensity
    write_ply(tmp_path / "c.ply", points, values, encoding="ascii")
    assert read_ply_xyzi(tmp_path / "b.ply") is None
    assert read_ply_xyzi(tmp_path / "c.ply") is None
