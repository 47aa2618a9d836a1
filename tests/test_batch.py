"""tritools.triangulate_many: order, one result per input, retries, executors (threads, dask), progress."""
from __future__ import annotations

import concurrent.futures as cf
import sys

import numpy as np
import pytest

import tritools
from tritools import Point, Status
from tritools.solve.batch import LOCAL_PROCESS_MIN_ITEMS, _local_executor
from tritools.scene import random_scene


def _problems(n=6, n_views=3, seed=11):
    scene = random_scene(n_views, n, noise_px=1.0, seed=seed)
    return [(scene.cameras, scene.regions(j)) for j in range(n)]


def _same(a, b, rtol=1e-12):
    # identical inputs through the same deterministic code (Clarabel is deterministic): equal to round-off;
    # rtol=1e-7 when one side is the batched delta-2 SDP (tritools.solve.sdp_batch: batched IPM vs Clarabel)
    assert a.status == b.status and a.certified_by == b.certified_by and a.delta == b.delta
    for name in ("gamma_lb", "gamma_ub"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None) and (x is None or x == pytest.approx(y, rel=rtol, abs=rtol))
    if a.X is not None:
        np.testing.assert_allclose(a.X, b.X, rtol=rtol, atol=rtol)


@pytest.mark.parametrize("path", ["auto", "sdp"])
def test_order_and_one_result_per_input_with_bad_items(path):
    good = _problems(4)
    nan_cams = np.array(good[0][0])
    nan_cams[1, 0, 0] = np.nan
    problems = [good[0], good[1], (nan_cams, good[2][1]), (good[2][0], good[2][1][:2]), "not a pair",
                (good[0][0], [Point([1.0, 2.0]), "region", Point([3.0, 4.0])]), good[2], good[3]]
    res = tritools.triangulate_many(problems, "corollary1", 2, 2, path=path, progress=False)
    assert len(res) == len(problems)
    assert [r.status for r in res] == [Status.OPTIMAL] * 2 + [Status.INVALID_INPUT] * 4 + [Status.OPTIMAL] * 2
    assert "NaN" in res[2].message and "cameras[1]" in res[2].message
    assert "one region per camera" in res[3].message
    assert "(cameras, regions) pair" in res[4].message
    assert "regions[1]" in res[5].message
    want = "verification" if path == "auto" else "sdp"
    assert {r.certified_by for r in res if r.optimal} == {want}
    # input order: each good result is the single call's result for that input
    for k, j in ((0, 0), (1, 1), (6, 2), (7, 3)):
        _same(res[k], tritools.triangulate(*good[j], "corollary1", 2, 2, path=path), 1e-9 if path == "auto" else 1e-7)


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="path"):
        tritools.triangulate_many(_problems(1), path="fast")
    with pytest.raises(ValueError, match="chunk_size"):
        tritools.triangulate_many(_problems(1), chunk_size=0)
    assert tritools.triangulate_many([], progress=False) == []


def test_retries_recorded_and_first_certified_kept():
    # theorem1 at delta 2 is invalid with three views (delta_min = 4): the retry certifies
    problems = _problems(2)
    res = tritools.triangulate_many(problems, "theorem1", 2, 2, retries=[("theorem1", 2), ("corollary1", 2)],
                                    progress=False)
    for r in res:
        assert r.status == Status.OPTIMAL and r.method == "corollary1" and r.certified_by == "verification"
        retried = [a for a in r.attempts if a.step == "retry"]
        assert [(a.method, a.delta) for a in retried] == [("theorem1", None), ("corollary1", 2)]
        assert retried[0].status == Status.INVALID_INPUT.value and r.attempts[0].status == Status.INVALID_INPUT.value
    # no retry certifies: the first result is kept with the whole chain recorded
    res = tritools.triangulate_many(problems[:1], "theorem1", 2, 2, retries=[("theorem1", 2)], progress=False)
    assert res[0].status == Status.INVALID_INPUT and len(res[0].attempts) == 2


def test_thread_pool_executor_gives_the_local_results():
    problems = _problems(5)
    local = tritools.triangulate_many(problems, "corollary1", 2, 2, path="sdp", progress=False)
    with cf.ThreadPoolExecutor(2) as ex:
        threaded = tritools.triangulate_many(problems, "corollary1", 2, 2, path="sdp", executor=ex, chunk_size=2,
                                             progress=False)
    for a, b in zip(local, threaded):
        _same(a, b)


class _FailingExecutor(cf.ThreadPoolExecutor):
    """Every task raises: the batch must still return one failed result per item."""

    def submit(self, fn, *args, **kwargs):
        def boom():
            raise RuntimeError("worker lost")
        return super().submit(boom)


def test_failed_executor_task_fails_its_items_only():
    problems = _problems(3)
    with _FailingExecutor(1) as ex:   # backend given: per-point items (not the in-process batched SDP)
        res = tritools.triangulate_many(problems, "corollary1", 2, 2, path="sdp", executor=ex, progress=False,
                                        backend="clarabel")
    assert [r.status for r in res] == [Status.SOLVER_FAILED] * 3
    assert all("worker lost" in r.message for r in res)


def test_dask_local_cluster_gives_the_local_results():
    distributed = pytest.importorskip(
        "distributed", reason="dask.distributed not installed (pip install '.[distributed]')")
    problems = _problems(4, n_views=2) + _problems(2, n_views=4, seed=3)
    local = tritools.triangulate_many(problems, "corollary1", 2, 2, path="sdp", progress=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cl, \
            distributed.Client(cl) as client:
        remote = tritools.triangulate_many(problems, "corollary1", 2, 2, path="sdp", executor=client, chunk_size=2,
                                           progress=False)
        auto = tritools.triangulate_many(problems, "corollary1", 2, 2, executor=client, progress=False)
    for a, b in zip(local, remote):
        _same(a, b)
    assert all(r.certified_by == "verification" for r in auto)


def test_progress_works_without_tqdm(monkeypatch):
    monkeypatch.setitem(sys.modules, "tqdm", None)      # import tqdm -> ImportError
    res = tritools.triangulate_many(_problems(2), progress=True)
    assert all(r.optimal for r in res)


def test_progress_bar_with_tqdm(capsys):
    pytest.importorskip("tqdm", reason="tqdm not installed (pip install '.[progress]')")
    res = tritools.triangulate_many(_problems(2), progress=True)
    assert all(r.optimal for r in res)
    assert "triangulating" in capsys.readouterr().err


def test_default_executor_rule():
    assert _local_executor(LOCAL_PROCESS_MIN_ITEMS - 1, 10) is None
    ex = _local_executor(LOCAL_PROCESS_MIN_ITEMS, 1)
    try:
        import os
        if (os.cpu_count() or 1) < 2:
            assert ex is None
        else:
            assert isinstance(ex, cf.ProcessPoolExecutor)
            assert ex._mp_context.get_start_method() == "spawn"
    finally:
        if ex is not None:
            ex.shutdown()


@pytest.mark.parametrize("path", ["auto", "sdp"])
def test_extreme_item_does_not_lose_the_batch(path):
    # a point at 1e308 px (finite, overflows inside the vectorised paths) used to raise LinAlgError out of
    # triangulate_many, losing every result; now it gets its own status and the others are solved
    good = _problems(3)
    cams = good[0][0]
    huge = (cams, [Point([1e308, 1e308])] + list(good[0][1][1:]))
    with np.errstate(all="ignore"):
        res = tritools.triangulate_many([good[0], huge, good[1], good[2]], "corollary1", 2, 2, path=path,
                                        progress=False)
    assert len(res) == 4
    assert res[1].status in (Status.INVALID_INPUT, Status.SOLVER_FAILED, Status.NUMERICAL_FAILURE)
    assert not res[1].optimal
    alone = tritools.triangulate_many([good[0], good[1], good[2]], "corollary1", 2, 2, path=path, progress=False)
    for a, b in zip([res[0], res[2], res[3]], alone):
        assert a.status == b.status == Status.OPTIMAL
        assert a.gamma_ub == pytest.approx(b.gamma_ub, rel=1e-7)
