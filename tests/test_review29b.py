"""Review 29b (independent: bad input and output hygiene) -- the fixes.

F1: huge finite camera entries (1e200, 1e308) raised OverflowError out of ``triangulate`` (``validate_cameras``'s
power of two "at or just above" 1e308 is 2^1024; the exact centres' squared separation past the largest double), and
batches turned it into ``solver_failed`` rows."""
import math
import sys

import numpy as np
import pytest

import tritools
from sospoly.scaling import MAX_POW2_EXP, pow2_above, pow2_above_array

CAMS = np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]],
                 [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]],
                 [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 1]]], dtype=float)
PTS = np.array([[0.1, -0.05], [0.6, -0.05], [0.1, 0.45]])


@pytest.mark.parametrize("m", [0.0, -1.0, math.inf, math.nan, 5e-324, 1e-300, 0.75, 1.0, 3.0, 1e300,
                               2.0 ** 1023, 1e308, sys.float_info.max])
def test_pow2_above_is_a_finite_power_of_two_and_its_twin_agrees(m):
    k = pow2_above(m)
    assert math.isfinite(k) and k > 0 and math.frexp(k)[0] == 0.5          # a power of two
    assert pow2_above_array(np.array([m]))[0] == k
    if m > 0 and math.isfinite(m):
        assert m / k <= 2.0 and (m / k > 0.25 or math.frexp(m)[1] > MAX_POW2_EXP)
        assert (m / k) * k == m                                               # exact


@pytest.mark.parametrize("where, value", [((0, 0, 0), 1e308), ((0, 2, 3), 1e200), ((1, 0, 3), -1e300)])
def test_huge_camera_entries_give_a_result_not_an_exception(where, value):
    cams = CAMS.copy()
    cams[where] = value
    tritools.validate_cameras(cams)
    r = tritools.triangulate(cams, PTS)
    assert r.status in tuple(tritools.Status)
    if r.gamma_lb is not None and r.gamma_ub is not None:
        assert r.gamma_lb <= r.gamma_ub
    b = tritools.triangulate_points(cams, PTS[None])
    assert b.status[0] != "solver_failed", b.message[0]
    assert "OverflowError" not in b.message[0]


def test_a_camera_scaled_by_1e308_is_the_same_camera():
    cams = CAMS.copy()
    cams[0] = np.hstack([1e308 * np.eye(3), np.zeros((3, 1))])
    ref = tritools.triangulate(np.vstack([np.hstack([np.eye(3), np.zeros((3, 1))])[None], CAMS[1:]]), PTS)
    r = tritools.triangulate(cams, PTS)
    assert r.status == ref.status
    assert r.gamma_ub == pytest.approx(ref.gamma_ub, rel=1e-9)


# F2: ``tritools colmap --keypoint-radius 1e200`` ended "internal error: OverflowError" (exit 1): the discs' D = r^2 I
# was inf on the diagonal and NaN off it (inf * 0), and the exact recession test made a Fraction of inf.
def test_colmap_with_a_huge_keypoint_radius_finishes(tmp_path):
    import subprocess

    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    a, _ = synthetic_arrays(n_points=6, n_images=4, camera="PINHOLE", seed=3)
    write_model_arrays(a, tmp_path / "in", "txt")
    p = subprocess.run([sys.executable, "-m", "tritools", "colmap", str(tmp_path / "in"), str(tmp_path / "out"),
                        "--keypoint-radius", "1e200", "--max-delta", "2"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "Warning" not in p.stderr and "Error" not in p.stderr, p.stderr
    rows = [line.split() for line in (tmp_path / "out" / "points3D_uncertainty.txt").read_text().splitlines()
            if not line.startswith("#")]
    assert len(rows) == 6
    assert all(r[5] in ("inf", "nan") or float(r[5]) > 1e6 for r in rows)   # no small radius claimed


def test_disc_blocks_are_diagonal_without_nan():
    from tritools.uncertain.discs import disc_blocks

    centres = np.zeros((2, 1, 2))
    (blk,) = disc_blocks(centres, np.array([[2.0], [1e200]]))
    assert np.array_equal(blk.D[0], 4.0 * np.eye(2)) and np.array_equal(blk.Dinv[0], 0.25 * np.eye(2))
    assert blk.D[1, 0, 0] == np.inf and blk.D[1, 0, 1] == 0.0 and not np.isnan(blk.D).any()
    assert not np.isnan(blk.L).any() and not np.isnan(blk.Dinv).any()


# F4: Ctrl-C during ``tritools colmap --workers 2`` (or the default local pool) ran on for over a minute: the pool's
# exit waited for every running task, and a worker inside a Clarabel solve sees its SIGINT only when it returns.
def test_workers_stop_at_once_when_the_command_is_interrupted():
    import time
    from types import SimpleNamespace

    from tritools.cli.workers import executor_from_args

    t0 = time.monotonic()
    procs = []
    with pytest.raises(KeyboardInterrupt):
        with executor_from_args(SimpleNamespace(workers=2, scheduler=None)) as ex:
            futures = [ex.submit(time.sleep, 60) for _ in range(4)]     # 2 x 60 s of work per worker
            procs = list(ex._processes.values())
            time.sleep(0.5)
            raise KeyboardInterrupt
    _all_exit(procs)
    assert time.monotonic() - t0 < 30
    assert all(f.done() for f in futures)


def _all_exit(procs, seconds: float = 10.0) -> None:
    import time

    end = time.monotonic() + seconds
    while any(p.is_alive() for p in procs) and time.monotonic() < end:
        time.sleep(0.1)
    assert procs and all(not p.is_alive() for p in procs), procs


def test_stop_pool_terminates_running_workers():
    import concurrent.futures as cf
    import multiprocessing
    import time

    from tritools.solve.batch import stop_pool

    ex = cf.ProcessPoolExecutor(max_workers=2, mp_context=multiprocessing.get_context("spawn"))
    futures = [ex.submit(time.sleep, 60) for _ in range(3)]
    procs = list(ex._processes.values())
    t0 = time.monotonic()
    stop_pool(ex)
    _all_exit(procs)
    assert time.monotonic() - t0 < 20
    cf.wait(futures, timeout=10)                    # the pool's manager settles the broken tasks' futures
    assert all(f.done() for f in futures)


def _model(tmp_path, fmt="txt", n_points=12):
    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    a, _ = synthetic_arrays(n_points=n_points, n_images=5, camera="PINHOLE", seed=4)
    write_model_arrays(a, tmp_path / "in", fmt)
    return tmp_path / "in"


def _colmap(*args):
    import subprocess

    return subprocess.run([sys.executable, "-m", "tritools", "colmap", *map(str, args)], capture_output=True,
                          text=True, timeout=120)


# F3: ``--export IN/fused.ply`` replaced the user's file in IN_DIR; OUT_DIR inside IN_DIR was accepted.
def test_outputs_inside_the_input_folder_are_refused(tmp_path):
    src = _model(tmp_path)
    (src / "fused.ply").write_text("the user's point cloud")
    before = {f.name: f.read_bytes() for f in src.iterdir()}
    for args in ([src, tmp_path / "out", "--export", src / "fused.ply"],
                 [src, tmp_path / "out", "--export", src / "new" / "p.npz"],
                 [src, src / "sub"]):
        p = _colmap(*args, "--max-delta", "2")
        assert p.returncode == 2, (args, p.stderr)
        assert len(p.stderr.strip().splitlines()) == 1 and "inside IN_DIR" in p.stderr, p.stderr
    assert {f.name: f.read_bytes() for f in src.iterdir()} == before       # nothing written, nothing created
    assert not (tmp_path / "out").exists()


# F7: points removed by the quality filters were reported CERTIFIED = 1, UPDATED = 1 (sidecar and JSON).
def test_points_removed_by_the_filters_are_not_reported_as_written(tmp_path):
    import json

    from tritools.io.colmap import read_model
    from tritools.sfm.certificates import REMOVED_MESSAGE, read_certificates

    src = _model(tmp_path, n_points=30)
    p = _colmap(src, tmp_path / "out", "--max-error", "0", "--json", "--max-delta", "2")
    assert p.returncode == 0, p.stderr
    written = set(read_model(tmp_path / "out").points3D)
    side = read_certificates(tmp_path / "out")
    records = {r["point3D_id"]: r for r in json.loads(p.stdout)["points"]}
    assert len(side) == len(records) == 30 and len(written) < 30
    for pid, c in side.items():
        if pid in written:
            continue
        assert not c.updated and not c.result.optimal or c.result.status != "optimal"
        assert REMOVED_MESSAGE in c.result.message
        rec = records[pid]
        assert rec["kept"] is False and rec["certified"] is False and rec["updated"] is False
        assert REMOVED_MESSAGE in rec["message"]
    header = (tmp_path / "out" / "points3D_certificates.txt").read_text().splitlines()
    count = [h for h in header if h.startswith("# Number of points:")][0]
    n_cert = sum(1 for line in header if line and not line.startswith("#") and line.split()[4] == "1")
    assert f"certified: {n_cert}," in count


# F5: a bad ``executor`` raised AttributeError from inside the batch (or was accepted silently).
@pytest.mark.parametrize("bad", ["x", 5, object()])
def test_a_bad_executor_is_a_type_error_naming_it(bad):
    with pytest.raises(TypeError, match="executor"):
        tritools.triangulate_many([(CAMS, PTS)], executor=bad)


@pytest.fixture
def house_copy(oxford_data, tmp_path):
    """A copy of the house sequence in tmp_path/house (the conftest's ``oxford_data`` skips without the data)."""
    import shutil
    from pathlib import Path

    shutil.copytree(Path(oxford_data) / "house", tmp_path / "house")
    return tmp_path / "house"


# F6: ``tritools dataset`` on a sequence with an empty nview-corners file ended "internal error" (exit 1).
def test_an_empty_sequence_is_a_one_line_error(house_copy, tmp_path):
    import subprocess

    nview = next((tmp_path / "house").glob("*.nview-corners"))
    nview.write_text("")
    p = subprocess.run([sys.executable, "-m", "tritools", "dataset", "house", "--data-dir", str(tmp_path)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "--world-frame" in p.stderr


# F1's batch side: an unexpected exception while a robust batch set up one problem's search (OverflowError from
# the vectorised camera check) raised out of ``triangulate_many(..., robust=c)``: every point of the batch was lost.
def test_a_robust_batch_keeps_every_point_when_a_search_fails_to_start(monkeypatch):
    from tritools.model import cameras as cam_mod
    from tritools.solve import robust as robust_mod

    SENTINEL = 12345.678
    real_init, real_problems = robust_mod.TlsSearch.__init__, cam_mod.camera_problems

    def init(self, cams, *a, **k):
        if np.any(np.asarray(cams) == SENTINEL):
            raise OverflowError("math range error")
        real_init(self, cams, *a, **k)

    def problems(C):
        if np.any(np.asarray(C) == SENTINEL):
            raise OverflowError("math range error")
        return real_problems(C)

    monkeypatch.setattr(robust_mod.TlsSearch, "__init__", init)
    monkeypatch.setattr(cam_mod, "camera_problems", problems)
    rng = np.random.default_rng(0)
    good = []
    for _ in range(2):
        X = rng.normal(size=3) + [0, 0, 4]
        x = np.array([P[:2] @ np.append(X, 1) / (P[2] @ np.append(X, 1)) for P in CAMS])
        good.append((CAMS.copy(), x))
    bad = CAMS.copy()
    bad[0, 0, 3] = SENTINEL
    res = tritools.triangulate_many([good[0], (bad, PTS), good[1]], robust=5.0, progress=False)
    assert len(res) == 3
    assert res[0].status == "optimal" and res[2].status == "optimal"
    assert res[1].status in ("solver_failed", "invalid_input") and "OverflowError" in res[1].message


# F9: ``tritools colmap --total-time-limit 2`` on 20,000 points ran 22 s (10 s without a limit): the rows still open
# after the end were turned into per-point items and sent through the process pool one by one.
def test_rows_open_past_the_end_get_their_rows_of_last_resort_at_once(monkeypatch):
    import time

    from tritools.solve.stages import batch as sb

    real_verify, calls = sb.verify_points, []

    def slow_verify(*a, **k):
        time.sleep(0.3)                          # the whole call's end passes inside the batch stages
        return real_verify(*a, **k)

    def items(self, rows=None):
        calls.append(len(self.open_rows()))
        raise AssertionError("past the end, no per-point items are built")

    def expired_items(items, *a):
        calls.append(len(items))
        return real_expired_items(items, *a)

    from tritools.solve import batch as batch_mod
    real_expired_items = batch_mod._expired_items
    monkeypatch.setattr(sb, "verify_points", slow_verify)
    monkeypatch.setattr(sb.BatchContext, "items", items)
    monkeypatch.setattr(batch_mod, "_expired_items", expired_items)
    rng = np.random.default_rng(1)
    M, N = 40, 20                                # 20 views: beyond the batched SDP's stacks
    cams = []
    for a in np.linspace(0, 2 * np.pi, N, endpoint=False):
        c = np.array([6 * np.cos(a), 0.3 * np.sin(3 * a), 6 * np.sin(a)])
        z = -c / np.linalg.norm(c)
        u = np.cross([0.0, 1.0, 0.0], z)
        u /= np.linalg.norm(u)
        R = np.vstack([u, np.cross(z, u), z])
        cams.append(np.diag([800.0, 800.0, 1.0]) @ np.hstack([R, (-R @ c)[:, None]]))
    cams = np.array(cams)
    X = rng.normal(scale=0.5, size=(M, 3))
    h = np.einsum("nij,mj->mni", cams, np.c_[X, np.ones(M)])
    x = h[..., :2] / h[..., 2:] + rng.normal(scale=0.5, size=(M, N, 2))
    x[:, :4] += 80.0                             # wrong matches: verification leaves every row open
    res = tritools.triangulate_points(cams, x, total_time_limit=0.2, layout="points_views")
    assert not calls, calls
    solved = tritools.solve.batch.solve_point_stack(np.broadcast_to(cams, (M,) + cams.shape), x,
                                                    tritools.TriangulationOptions(total_time_limit=0.2))
    assert not calls, calls
    assert len(solved.objects) + len(solved.stacked) == M
    assert len(res.status) == M and all(s == "time_limit" for s in res.status)
    assert np.all(np.isfinite(res.gamma_ub))


# F17: ``--export LINK.ply`` with LINK a symlink to a file of the input model overwrote that file.
def test_an_export_through_a_symlink_into_the_input_is_refused(tmp_path):
    src = _model(tmp_path)
    target = src / "points3D.txt"
    before = target.read_bytes()
    (tmp_path / "link.ply").symlink_to(target)
    p = _colmap(src, tmp_path / "out", "--export", tmp_path / "link.ply", "--max-delta", "2")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert target.read_bytes() == before and not (tmp_path / "out").exists()


# F14: ``retriangulate_folder(output_format='json')`` raised KeyError from deep inside.
@pytest.mark.parametrize("field", ["output_format", "input_format"])
def test_a_bad_model_format_is_refused_by_name(tmp_path, field):
    from tritools.sfm import OptionError, retriangulate_folder

    src = _model(tmp_path)
    with pytest.raises(OptionError, match=field):
        retriangulate_folder(src, tmp_path / "out", **{field: "json"})
    assert not (tmp_path / "out").exists()


# F11: ``colmap-from-oxford NAME OUT`` wrote its model into the sequence folder it reads.
def test_colmap_from_oxford_never_writes_into_the_sequence(house_copy, tmp_path):
    import subprocess

    before = sorted(f.name for f in (tmp_path / "house").iterdir())
    for out in (tmp_path / "house", tmp_path / "house" / "model"):
        p = subprocess.run([sys.executable, "-m", "tritools", "colmap-from-oxford", "house", str(out), "--data-dir",
                            str(tmp_path)], capture_output=True, text=True, timeout=120)
        assert p.returncode == 2 and "sequence folder" in p.stderr, p.stderr
    assert sorted(f.name for f in (tmp_path / "house").iterdir()) == before


# F15: SIGHUP (the terminal closed) killed ``tritools colmap`` and left its staging folder in OUT_DIR.
@pytest.mark.slow
def test_sighup_unwinds_like_sigterm(tmp_path):
    import os
    import signal

    from tests.cli_util import colmap_signalled

    rc, err, out = colmap_signalled(tmp_path, signal.SIGHUP)
    if rc == 0:
        pytest.skip("the run finished before the signal")
    assert rc == 128 + signal.SIGHUP and err.strip().endswith("tritools: SIGHUP"), (rc, err)
    assert sorted(os.listdir(out)) == ["notes.txt"]


def test_terminated_carries_its_signal():
    import signal

    from tritools.startup import EXIT_TERMINATED, TERMINATED_MESSAGE, Terminated

    assert Terminated().exit_code == EXIT_TERMINATED and Terminated().message == TERMINATED_MESSAGE
    if hasattr(signal, "SIGHUP"):
        t = Terminated(signal.SIGHUP)
        assert t.exit_code == 129 and t.message == "tritools: SIGHUP" and isinstance(t, KeyboardInterrupt)
