"""Threads inside one fit (:mod:`studio.threads`): a batch's chunks run side by side and give the
results of one thread to the last bit; a body's mesh and cost do not depend on the batch it is in."""

from __future__ import annotations

import multiprocessing
import threading

import numpy as np
import pytest

from calibration import Camera
from studio.body import BodyModel
from studio.cost import SilhouetteTarget
from studio.fit.objective import BATCH, CylinderObjective, FrameObjective
from studio.render import silhouette
from studio.threads import chunk_ranges, map_chunks, set_threads, threads


@pytest.fixture
def two_threads():
    set_threads(2)
    yield
    set_threads(None)


@pytest.fixture(scope="module")
def scene():
    model = BodyModel.load("female")
    cams = [Camera.look_at(f"cam{k}", [3.0 * np.cos(a), 3.0 * np.sin(a), 1.5], [0, 0, 0.9], 90.0, (96, 72),
                           np.zeros(5)) for k, a in enumerate((0.4, 2.2, 4.0))]
    shape, pose = model.mean_shape(), model.default_pose()
    masks = [silhouette(c, model.vertices(shape, pose), model.faces) for c in cams]
    return model, cams, {1: SilhouetteTarget.build(masks, level=1)}, shape, pose


@pytest.mark.parametrize("n_threads", [1, 2, 3])
def test_chunk_ranges_cover_the_batch_in_near_equal_chunks_for_every_thread(n_threads):
    set_threads(n_threads)
    try:
        for n in (0, 1, 2, 3, 15, 16, 17, 40, 41, 51, 80):
            r = chunk_ranges(n, BATCH)
            assert [i for a, b in r for i in range(a, b)] == list(range(n))
            sizes = [b - a for a, b in r]
            assert all(s <= BATCH for s in sizes) and (n < 2 or min(sizes) >= 2)
            assert max(sizes, default=0) - min(sizes, default=0) <= 1
            if n >= 2 * n_threads * 2 and n_threads > 1:  # enough for every thread: an even share each
                assert len(r) % n_threads == 0
        assert len(chunk_ranges(80, 16)) == {1: 5, 2: 6, 3: 6}[n_threads]  # a particle filter's batch
    finally:
        set_threads(None)


def test_map_chunks_keeps_order_runs_on_threads_and_nests_without_waiting(two_threads):
    names = set()

    def square(i):
        names.add(threading.current_thread().name)
        return map_chunks(lambda j: j * j, [i])[0]  # a chunk that maps again runs in its own thread

    assert map_chunks(square, list(range(20))) == [i * i for i in range(20)]
    assert names and all(n.startswith("studio-batch") for n in names)
    with pytest.raises(ZeroDivisionError):  # a chunk's error reaches the caller
        map_chunks(lambda i: 1 // i, [1, 0, 2])


def test_thread_count_is_checked_and_a_worker_process_runs_one():
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="threads"):
            set_threads(bad)
    assert threads() >= 1
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        assert pool.apply(threads) == 1  # the workers already use the cores


@pytest.mark.parametrize("cls", [FrameObjective, CylinderObjective])
def test_costs_on_threads_equal_one_thread_and_each_body_alone(scene, cls):
    """80 particles of one shape (6 chunks on 2 threads, 5 on one) and each particle evaluated
    alone give the same costs to the last bit."""
    model, cams, targets, shape, pose = scene
    obj = cls(model, cams, targets, shape)
    rng = np.random.default_rng(3)
    X = obj.pack(shape, pose)[None] + rng.normal(0.0, 0.05, (80, obj.size))
    alone = np.concatenate([obj(x[None], 1) for x in X])
    for n in (1, 2, 3):
        set_threads(n)
        try:
            assert len(obj.chunks(X)) == {1: 5, 2: 6, 3: 6}[n]
            np.testing.assert_array_equal(obj(X, 1), alone)
        finally:
            set_threads(None)


def test_bodies_of_several_shapes_keep_their_batches_of_sixteen(scene):
    """A Jacobian's bodies (pose steps share the shape, shape steps do not) are evaluated in the
    batches of ``BATCH`` they always were, whatever the thread count: a body's shape deformation
    depends on its batch (BLAS gemm, or gemv for a batch of one shape) by 1e-9 m, which would
    otherwise move the fits."""
    model, cams, targets, _, pose = scene
    beta = np.random.default_rng(4).normal(0.0, 0.5, model.n_shape) * np.sqrt(model.eigenvalues)
    obj = FrameObjective(model, cams, targets, beta, n_shape_free=20)  # products of non-zero shapes
    x = obj.pack(beta, pose)
    J = np.repeat(x[None], obj.size + 1, axis=0)
    J[1:] += np.diag(np.full(obj.size, 1e-3))
    shapes, poses = obj.split(J)
    poses = model.clip_pose(poses)
    want = np.concatenate([model.vertices_batch(shapes[i : i + BATCH], poses[i : i + BATCH], free_shape=20)
                           for i in range(0, len(J), BATCH)])
    for n in (1, 2, 3):
        set_threads(n)
        try:
            assert obj.chunks(J) == [(i, min(i + BATCH, len(J))) for i in range(0, len(J), BATCH)]
            np.testing.assert_array_equal(obj.meshes(J), want)
        finally:
            set_threads(None)
    # the batch matters: the same bodies cut otherwise are not all the same to the last bit
    other = np.concatenate([model.vertices_batch(shapes[i : i + 13], poses[i : i + 13], free_shape=20)
                            for i in range(0, len(J), 13)])
    assert not np.array_equal(other, want)
    np.testing.assert_allclose(other, want, atol=1e-7)
