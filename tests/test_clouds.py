"""Clouds read from the work directory when needed, under one memory budget (issue 48).

What is kept must change the time a job takes, never a number: a cloud read from its PLY gives
the arrays a held one gives, fine registration and the report give the same values whether the
budget keeps everything or nothing, and a job through the CLI writes the same result with
``--cloud-memory 0`` as with no limit.
"""

from __future__ import annotations

import gc
import json

import numpy as np
import pytest

from nbcalib.clouds import Cloud, MemoryBudget, nbytes
from nbcalib.io.ply import read_ply_vertex_header, write_ply

# ---------------------------------------------------------------------------- the budget


def test_budget_keeps_what_fits_and_pushes_nothing_out():
    budget = MemoryBudget(100)
    made = []

    def make(n):
        def f():
            made.append(n)
            return np.zeros(n, dtype=np.uint8)

        return f

    a = budget.get("a", make(60))
    assert budget.get("a", make(60)) is a and made == [60]  # kept: made once
    b = budget.get("b", make(60))  # does not fit: handed over, not kept, "a" stays
    assert b.size == 60 and budget.used == 60
    budget.get("b", make(60))
    assert made == [60, 60, 60]
    budget.get("c", make(40))  # fits exactly
    assert budget.used == 100
    budget.drop("a")
    assert budget.used == 40
    budget.drop("a")  # nothing to drop: nothing happens
    assert budget.used == 40


def test_budget_share_leaves_room():
    budget = MemoryBudget(100)
    budget.get("big", lambda: np.zeros(70, np.uint8), share=0.75)
    budget.get("bigger", lambda: np.zeros(10, np.uint8), share=0.75)  # 80 > 75: not kept
    assert budget.used == 70
    budget.get("small", lambda: np.zeros(30, np.uint8))  # the room left
    assert budget.used == 100


def test_budget_limits():
    assert MemoryBudget(None).get("x", lambda: np.zeros(10**6)) is not None
    none = MemoryBudget(0)
    none.get("x", lambda: np.zeros(10))
    assert none.used == 0
    with pytest.raises(ValueError, match="at least 0"):
        MemoryBudget(-1)
    assert nbytes((np.zeros(3), [np.zeros(2, np.int32)], "text")) == 24 + 8


# ---------------------------------------------------------------------------- the cloud


@pytest.fixture()
def ply(tmp_path, rng):
    points = rng.normal(size=(5000, 3)).astype(np.float32)
    values = rng.random(5000).astype(np.float32)
    path = tmp_path / "pair.ply"
    write_ply(path, points, values)
    return path, points.astype(np.float64), values.astype(np.float64)


def test_a_read_cloud_gives_the_held_arrays(ply):
    path, points, values = ply
    size, names = read_ply_vertex_header(path)
    assert size == 5000 and names == ["x", "y", "z", "intensity"]
    read = Cloud(path=path, size=size)
    held = Cloud(points, values)
    for cloud in (read, held):
        p, v = cloud.arrays()
        assert p.dtype == np.float64 and p.flags.c_contiguous and v.dtype == np.float64
        assert np.array_equal(p, points) and np.array_equal(v, values)
        assert len(cloud) == 5000
    assert held.arrays()[0] is points  # held: the arrays given, not copies
    assert read.held_in_memory is False and held.held_in_memory is True


def test_held_reads_once_and_lets_go(ply, monkeypatch):
    import nbcalib.clouds as clouds

    path, points, _ = ply
    reads = []
    real = clouds._read_ply_cloud
    monkeypatch.setattr(clouds, "_read_ply_cloud", lambda p: reads.append(p) or real(p))
    cloud = Cloud(path=path, size=5000, budget=MemoryBudget(0))
    with cloud.held():
        with cloud.held():  # nested: still the same values, not read again
            assert np.array_equal(cloud.points, points)
            rows, values = cloud.rows(np.array([4, 0, 7]))
            assert rows.dtype == np.float64 and np.array_equal(rows, points[[4, 0, 7]])
            assert np.array_equal(values, cloud.intensities[[4, 0, 7]])
    assert len(reads) == 1
    assert np.array_equal(cloud.points, points) and len(reads) == 2  # let go: read again
    kept = Cloud(path=path, size=5000, budget=MemoryBudget(None))
    assert kept.points is not None and kept.points is not None
    assert len(reads) == 3  # the budget keeps the file's values


def test_a_cloud_takes_its_products_with_it(ply):
    path, _, _ = ply
    budget = MemoryBudget(None)
    cloud = Cloud(path=path, size=5000, budget=budget)
    assert len(cloud.points) == 5000
    cloud.memo("keys", lambda: np.zeros(5000, np.float32))
    assert budget.used == 5000 * 16 + 5000 * 4  # float32 values, not float64
    del cloud
    gc.collect()
    assert budget.used == 0


def test_the_cheapest_products_leave_room_for_the_dearest(ply):
    """The file's values (a read) fill at most a quarter of the budget, a visible set all."""
    from nbcalib.clouds import SHARES

    path, _, _ = ply
    file_bytes = 5000 * 16
    budget = MemoryBudget(int(file_bytes / SHARES["file"]) - 1)  # just too small for them
    cloud = Cloud(path=path, size=5000, budget=budget)
    assert len(cloud.points) == 5000 and budget.used == 0  # read, not kept
    cloud.memo(("visible", 1), lambda: np.zeros(2 * 5000, np.int32))
    assert budget.used == 5000 * 8  # kept
    roomy = Cloud(path=path, size=5000, budget=MemoryBudget(int(file_bytes / SHARES["file"])))
    assert len(roomy.points) == 5000 and roomy.budget.used == file_bytes


def test_a_cloud_is_given_arrays_or_a_file(ply):
    path, points, values = ply
    with pytest.raises(ValueError, match="either"):
        Cloud(points, values, path=path)
    with pytest.raises(ValueError, match="intensities"):
        Cloud(points)
    with pytest.raises(ValueError, match="size"):
        Cloud(path=path)


# ------------------------------------------------------------------- fine registration


def _pairs(tmp_path, rng, budget):
    """A small textured box seen by one camera, its cloud held and read from a file."""
    from nbcalib.camera import example_camera
    from nbcalib.registration.pair import RegistrationPair
    from nbcalib.teaching import textured_box

    camera = example_camera("pinhole", 320, 240)
    image, points, values = textured_box(camera, 6.0, rng, n=6000)
    path = tmp_path / "box.ply"
    write_ply(path, points.astype(np.float32), values.astype(np.float32))
    points = points.astype(np.float32).astype(np.float64)
    values = values.astype(np.float32).astype(np.float64)
    held = RegistrationPair(camera, image, points, values, "box")
    cloud = Cloud(path=path, size=len(points), budget=budget)
    read = RegistrationPair(camera, image, name="box", cloud=cloud)
    return np.eye(4), held, read


@pytest.mark.parametrize("limit", [0, None])
@pytest.mark.parametrize("cost", ["regional", "nid"])
def test_costs_and_visible_sets_do_not_depend_on_the_budget(tmp_path, rng, limit, cost):
    from nbcalib.registration.costs import build_cost
    from nbcalib.registration.pair import visible_subset
    from nbcalib.registration.refine import RefineConfig

    T, held, read = _pairs(tmp_path, rng, MemoryBudget(limit))
    config = RefineConfig(
        cost=cost, points_per_pixel=0.05, min_sampled_points=2000, min_class_points=100
    )
    for _ in range(2):  # the second time from what the budget kept (or not)
        a, counts_a = build_cost([held], T, config)
        b, counts_b = build_cost([read], T, config)
        assert counts_a == counts_b
        assert a.value_and_grad(T)[0] == b.value_and_grad(T)[0]
        assert np.array_equal(a.value_and_grad(T)[1], b.value_and_grad(T)[1])
        assert np.array_equal(visible_subset(held, T, config), visible_subset(read, T, config))
    if cost == "nid":
        assert np.array_equal(held.classes, read.classes)


def test_visibility_is_kept_for_the_last_two_poses(tmp_path, rng):
    from nbcalib.transforms import offset_pose

    T, _, read = _pairs(tmp_path, rng, MemoryBudget(None))
    poses = [offset_pose(T, 0.2, 0.01, seed) for seed in range(3)]
    first = read.visibility(poses[0], 0.1, 0)
    assert first[0].dtype == np.int32 and first[1].dtype == np.int32  # kept compact
    assert not first[0].flags.writeable  # shared by every call at the pose
    assert read.visibility(poses[0], 0.1, 0)[0] is first[0]
    kept = read.cloud.budget.used
    read.visibility(poses[1], 0.1, 0)
    two = read.cloud.budget.used
    read.visibility(poses[2], 0.1, 0)
    assert read.cloud.budget.used == pytest.approx(two, rel=0.2) and two > kept
    again = read.visibility(poses[0], 0.1, 0)  # made again: the same
    assert all(np.array_equal(x, y) for x, y in zip(first, again))


# --------------------------------------------------------------------------- the CLI


def test_a_job_gives_the_same_result_whatever_it_keeps(tmp_path):
    """``--cloud-memory 0`` reads every cloud again at every step: the same calib.json."""
    from nbcalib.cli import main

    synth = tmp_path / "synth"
    assert main(["synth", str(synth), "--lidar", "livox", "--pairs", "2", "-q", "--format", "bag2",
                 "--duration", "0.3", "--image-size", "320x240", "--seed", "4"]) == 0  # fmt: skip
    inputs = sorted(str(p) for p in synth.glob("pair_*"))
    gt = json.loads((synth / "ground_truth.json").read_text())
    init = ",".join(str(v) for v in gt["T_lidar_camera"])
    results = []
    for memory in ("0", "none"):
        work = tmp_path / f"work_{memory}"
        status = main(["run", *inputs, str(work), "--no-matching", f"--init={init}",
                       "--cloud-memory", memory, "--max-outer", "2", "-q"])  # fmt: skip
        assert status == 0
        calib = json.loads((work / "calib.json").read_text())
        results.append((calib["results"], calib["nbcalib"]["quality"]["covariance"]))
    assert results[0] == results[1]
