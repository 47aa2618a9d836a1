"""Regression tests for the defects listed in issues #14 (bounded resources, clean failures) and #15 (SfM
workflows) that no other test file reproduces with the original input.  Each test names the defect it
reproduces; the inputs are the ones of the issue, with a short time limit where the original ran for minutes.

Timing: no assertion on speed beyond "returned within a generous multiple of its time limit" (a hang or a
run of minutes is what these tests catch); the whole file runs in well under a minute.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

import sospoly
import tritools
from tritools import Ellipse, EllipseBorder, Polytope, Status
from tritools.solve.options import TRIANGULATION_BUDGET, TriangulationOptions

#: three cameras and the exact projections of X_TRUE (gamma* = 0, certified by verification in milliseconds).
CAMS = np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]],
                 [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]],
                 [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 1]]], dtype=float)
X_TRUE = np.array([0.2, -0.1, 1.0])
_H = CAMS @ np.append(X_TRUE, 1.0)
PTS = _H[:, :2] / _H[:, 2:]
#: wall time allowed beyond a time limit before calling it a hang: one solver iteration of the largest program
#: the default memory budget admits can take ~10 s on a busy 2-core machine (the limit is checked between
#: iterations).
SLACK = 40.0
MISLEADING = ("equal up to scale", "rank < 3", "coincide")


# ----------------------------------------------------------------------------- #14: misleading diagnoses
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_cameras_times_1e300_are_the_same_cameras():
    """#14: cameras x 1e300 were diagnosed "cameras are all equal up to scale" (later: "all camera centres
    coincide"); a camera's scale is irrelevant, so the answer is that of the unscaled cameras."""
    ref = tritools.triangulate(CAMS, PTS)
    for k in (1e300, -1e300, 1e-300):
        res = tritools.triangulate(k * CAMS, PTS)
        assert res.status == ref.status == Status.OPTIMAL, (k, res.status, res.message)
        np.testing.assert_allclose(res.X, X_TRUE, atol=1e-9)
    (many,) = tritools.triangulate_many([(1e300 * CAMS, PTS)], progress=False)
    assert many.status == Status.OPTIMAL and np.allclose(many.X, X_TRUE, atol=1e-9)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("k", [1e20, 1e100, 1e300])
def test_points_at_1e300_are_not_blamed_on_the_cameras(k):
    """#14: image points at 1e300 were diagnosed "rank < 3" (later: "all camera centres coincide"), and points at
    1e20 raised numpy's LinAlgError out of triangulate.  Now: a result whose status and message name the data."""
    for res in (tritools.triangulate(CAMS, k * PTS), tritools.triangulate_many([(CAMS, k * PTS)], progress=False)[0]):
        assert isinstance(res, tritools.TriangulationResult)
        assert res.status == Status.NUMERICAL_FAILURE and not res.optimal, (res.status, res.message)
        assert "too large" in res.message and not any(m in res.message for m in MISLEADING[:2])
        assert "centres coincide" not in res.message



# ----------------------------------------------------------------------------- #14: input types
@pytest.mark.parametrize("cams", [CAMS.astype(complex), CAMS + 1e-3j, CAMS.astype(object), CAMS.astype(str)],
                         ids=["complex-real", "complex", "object", "str"])
def test_complex_object_and_string_cameras_are_refused_on_every_path(cams):
    """#14: complex cameras were reduced to their real part and certified (triangulate_points still did it)."""
    from tritools.sfm import certify_stack

    dtype = np.asarray(cams).dtype.name
    with pytest.raises(ValueError, match=f"cameras must be real numbers, got {dtype[:3]}"):
        tritools.triangulate(cams, PTS)
    with pytest.raises(ValueError, match="cameras must be real numbers"):
        tritools.triangulate_points(cams, PTS[None], progress=False)
    with pytest.raises(ValueError, match="cameras must be real numbers"):
        certify_stack(np.asarray(cams)[None], PTS[None])
    (res,) = tritools.triangulate_many([(cams, PTS)], progress=False)     # a batch never raises: a status
    assert res.status == Status.INVALID_INPUT and "cameras must be real numbers" in res.message


def test_complex_image_points_are_refused():
    with pytest.raises(ValueError, match="must be real numbers, got complex"):
        tritools.triangulate(CAMS, PTS + 0j)
    with pytest.raises(ValueError, match="points2d must be real numbers, got complex"):
        tritools.triangulate_points(CAMS, (PTS + 1e-9j)[None], progress=False)


def test_tolerances_none_means_the_defaults_and_anything_else_is_refused_by_name():
    """#14: ``tolerances=None`` raised AttributeError deep in the IPM (and gave numerical_error with Clarabel)."""
    import sospoly as sp
    from sospoly.solvers.backends import AutoBackend, ClarabelBackend, IpmBackend, get_backend

    x, y = sp.variables("x y")
    f = x**2 + y**2 - x                                     # min -1/4 at (1/2, 0)
    ps = sp.build_psatz(f, degree=2)
    comp = sp.compile_psatz(f, degree=2)
    runs = [lambda t: sp.solve_psatz(ps, tolerances=t), lambda t: sp.solve_psatz(ps, backend="ipm", tolerances=t),
            lambda t: sp.solve_psatz(ps, backend="auto", tolerances=t), lambda t: comp.solve(f, tolerances=t),
            lambda t: sp.solve_psatz(ps, backend=ClarabelBackend(t)),
            lambda t: sp.solve_psatz(ps, backend=IpmBackend(t)),
            lambda t: sp.minimize(f, tolerances=t), lambda t: sp.minimize(f, backend="ipm", tolerances=t)]
    for run in runs:
        res = run(None)
        assert res.status == sp.SolveStatus.OPTIMAL and res.lower_bound == pytest.approx(-0.25, abs=1e-6)
        with pytest.raises(TypeError, match="tolerances must be a sospoly.Tolerances, got float"):
            run(1e-6)
    for make in (ClarabelBackend, IpmBackend, AutoBackend, lambda t: get_backend("ipm", t)):
        with pytest.raises(TypeError, match="got str"):
            make("tight")
    assert tritools.triangulate(CAMS, PTS, tolerances=None).optimal
    with pytest.raises(TypeError, match="tolerances must be a sospoly.Tolerances"):
        tritools.triangulate(CAMS, PTS, tolerances={"gap_abs": 1e-6})


# ----------------------------------------------------------------------------- #14: resources
def _example4_variants():
    cams, regions = tritools.paper_example(4)
    x = [r.x for r in regions]
    w = 1e-12                                               # R = {y : ||(y - x_1) / w||_inf <= 1}
    return cams, {
        "filled ellipse D=1e30 I": [Ellipse(x[0], 1e30 * np.eye(2))] + list(regions[1:]),
        "filled ellipse D=1e-30 I": [Ellipse(x[0], 1e-30 * np.eye(2))] + list(regions[1:]),
        "four ellipse borders of radius 1e-8": [EllipseBorder.circle(c, 1e-8) for c in x],
        "a 1e-12 box": [Polytope(np.eye(2) / w, -x[0] / w)] + list(regions[1:]),
    }


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _assert_a_result(res):
    assert isinstance(res, tritools.TriangulationResult) and isinstance(res.status, Status)
    json.dumps(res.to_dict(), allow_nan=False)
    if res.status == Status.TIME_LIMIT:
        assert "time limit" in res.message


@pytest.mark.parametrize("name", list(_example4_variants()[1]))
def test_regions_that_ran_for_minutes_return_within_the_time_limit(name):
    """#14: with Theorem 1 these regions ran for minutes and could not be interrupted (no time limit)."""
    cams, variants = _example4_variants()
    if name == "a 1e-12 box":                               # the box really is 2e-12 wide around x_1
        V = variants[name][0].vertices
        assert len(V) == 4 and np.abs(V - variants[name][0].center).max() <= 1.01e-12
    res, elapsed = _timed(lambda: tritools.triangulate(cams, variants[name], "theorem1", time_limit=2))
    _assert_a_result(res)
    assert elapsed < 2 + SLACK, f"{name}: {elapsed:.1f} s"


def test_the_default_budget_bounds_every_point():
    """No single point may take minutes or gigabytes by default: every entry point starts from the same
    finite budget (the CLI flags and the COLMAP workflow included, see test_defaults_agree)."""
    b = TriangulationOptions().budget
    assert b == TRIANGULATION_BUDGET and b.time_limit <= 60 and b.max_bytes <= 2 * 2 ** 30
    assert TriangulationOptions().replace(time_limit=5).budget == sospoly.Budget(5, TRIANGULATION_BUDGET.max_bytes)


def _duplicated_views_scene(moved: float = 0.0):
    """#14's input: 5 views, two of them duplicates of others, one camera scaled by 1e17; ``moved``: the duplicates'
    keypoints moved by that many pixels (then two observations in one camera each, 5 distinct views)."""
    from tritools.scene import random_scene

    sc = random_scene(3, 1, noise_px=1.0, seed=1)
    cams = np.concatenate([sc.cameras, sc.cameras[:2]])
    cams[2] = cams[2] * 1e17
    return cams, np.concatenate([sc.points2d[0], sc.points2d[0][:2] + moved])


def test_exact_copies_are_solved_as_the_distinct_views():
    """#14's exact copies are one view each, weighted (tritools.solve.identical_views): Theorem 1's dense delta = 6
    program then has 3 views, and is certified."""
    cams, pts = _duplicated_views_scene()
    res = tritools.triangulate(cams, pts, "theorem1", delta=6, sparsity="none", time_limit=30)
    assert "views 3 repeats view 0" not in res.message and "view 3 repeats view 0" in res.message
    assert res.optimal and len(res.residuals) == 5


def test_duplicated_views_and_a_1e17_camera_give_a_status_not_a_memory_error():
    """#14: Theorem 1 on this scene let a MemoryError escape (an (8008, 286, 286) array in the IPM, the dense
    delta = 6 program).  The dense program is now refused by its size estimate before anything is allocated,
    and the default plan returns within its time limit.  (The duplicated cameras see moved keypoints: five views,
    not copies, which :func:`test_exact_copies_are_solved_as_the_distinct_views` reduces to three.)"""
    cams, pts = _duplicated_views_scene(moved=0.5)
    try:
        dense, elapsed = _timed(lambda: tritools.triangulate(cams, pts, "theorem1", delta=6, sparsity="none",
                                                            time_limit=30))
        res, elapsed_plan = _timed(lambda: tritools.triangulate(cams, pts, "theorem1", time_limit=2))
    except MemoryError:                                   # pragma: no cover - the defect
        pytest.fail("MemoryError")
    assert dense.status == Status.BUDGET_EXCEEDED and "Gram block of side 286" in dense.message
    assert "the memory budget 2 GiB" in dense.message and elapsed < 10     # (refused before building, wave 11)
    _assert_a_result(res)
    assert res.delta is not None and elapsed_plan < 2 + SLACK
    # the plan starts low, never at the refused dense delta = 6: first the degree-2 step on Theorem 1's two-view
    # minors (Corollary 1's epipolar constraints, docs/triangulation.md), then Theorem 1 from delta_min = 4
    assert [(a.method, a.delta) for a in res.attempts][:1] == [("corollary1", 2)]
    assert [a.delta for a in res.attempts if a.method == "theorem1"][:1] in ([], [4])


def test_dense_40_variable_quartic_gives_budget_exceeded_by_default():
    """#14: sospoly.minimize on 40 variables aborted the interpreter in native code (exit 134).  A quartic
    coupling all 40 variables has no sparsity to exploit: the default call refuses it by its estimate
    (the chained 40-variable case with sparsity="none" is tests/test_sparse_minimize.py)."""
    xs = sospoly.variables(" ".join(f"x{i}" for i in range(40)))
    s = sum(x * x for x in xs)
    res, elapsed = _timed(lambda: sospoly.minimize(s * s - sum(xs)))
    assert res.status == sospoly.SolveStatus.BUDGET_EXCEEDED and not res.optimal and res.lower_bound is None
    assert "exceeds the memory budget" in res.message and elapsed < 30


# ----------------------------------------------------------------------------- #14: executors
def _problems(n):
    from tritools.scene import random_scene

    sc = random_scene(3, n, noise_px=0.5, seed=7)
    return [(sc.cameras, sc.points2d[j]) for j in range(n)]


#: per-item SDPs (a back-end given: not the in-process batched SDP), so every item goes through the executor
PER_ITEM = dict(method="corollary1", delta=2, max_delta=2, path="sdp", backend="clarabel", progress=False)


def test_a_users_broken_process_pool_is_retried(caplog):
    """#14: a user's own ProcessPoolExecutor that broke (a worker killed) marked every remaining item
    solver_failed ("executor broke") without a retry; its unfinished items are now solved in this process."""
    import concurrent.futures as cf
    import multiprocessing
    import os

    problems = _problems(3)
    ref = tritools.triangulate_many(problems, **PER_ITEM)
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        with pytest.raises(cf.process.BrokenProcessPool):
            ex.submit(os._exit, 3).result()                       # the worker is killed: the pool is broken
        with caplog.at_level("WARNING", logger="tritools"):
            res = tritools.triangulate_many(problems, executor=ex, **PER_ITEM)
    assert [r.status for r in res] == [r.status for r in ref] and all(r.optimal for r in res)
    for a, b in zip(res, ref):
        np.testing.assert_allclose(a.X, b.X, rtol=1e-9)
    assert any("executor broke" in m and "retrying" in m for m in caplog.messages)


class _BreaksMidRun:
    """An executor whose second task dies with its pool (BrokenProcessPool), after the first one finished."""

    def __init__(self):
        self.calls = 0

    def submit(self, fn, *args, **kwargs):
        import concurrent.futures as cf

        self.calls += 1
        fut = cf.Future()
        if self.calls == 1:
            fut.set_result(fn(*args, **kwargs))
        else:
            fut.set_exception(cf.process.BrokenProcessPool("a worker was killed"))
        return fut


def test_a_pool_that_breaks_mid_run_loses_no_item():
    problems = _problems(4)
    ex = _BreaksMidRun()
    res = tritools.triangulate_many(problems, executor=ex, chunk_size=1, **PER_ITEM)
    assert ex.calls >= 2 and len(res) == 4 and all(r.optimal for r in res)
    assert not any("executor" in (r.message or "") for r in res)


# ----------------------------------------------------------------------------- #15 / #12: one set of defaults
def test_defaults_agree(monkeypatch, tmp_path, capsys):
    """triangulate, triangulate_many, triangulate_points, `tritools solve`, `tritools dataset` and `tritools colmap`
    (and the library's model path) build the same TriangulationOptions by default: method auto, path auto, the
    same per-point budget.  (#12 found Theorem 1/SDP on one path and Corollary 1/auto on another; #15 asked colmap
    for the flags of solve.)"""
    import tritools.solve.batch as batch
    import tritools.solve.triangulate as tri
    from tests.test_colmap import synthetic_model
    from tritools.cli import app as cli
    from tritools.io.colmap import write_binary_model
    from tritools.sfm import RetriangulationOptions, certify_stack, retriangulate
    from tritools.solve.options import DEFAULT_OPTIONS

    seen = {}

    def spy(name, module, attr, pick):
        real = getattr(module, attr)

        def wrapper(*args, **kwargs):
            seen.setdefault(name, []).append(pick(args, kwargs))
            return real(*args, **kwargs)
        monkeypatch.setattr(module, attr, wrapper)

    spy("per point", tri, "run_point", lambda a, k: a[2])
    spy("problems", batch, "solve_point_problems", lambda a, k: a[1])
    spy("stack", batch, "solve_point_stack", lambda a, k: a[2])

    def built(name, call):
        seen.clear()
        call()
        key = {"triangulate": "per point", "colmap": "stack", "certify_stack": "stack",
               "retriangulate": "stack"}.get(name, "problems")
        assert seen.get(key), (name, seen)
        return seen[key]

    paths = {
        "triangulate": lambda: tritools.triangulate(CAMS, PTS),
        "triangulate_many": lambda: tritools.triangulate_many([(CAMS, PTS)], progress=False),
        "triangulate_points": lambda: tritools.triangulate_points(CAMS, PTS[None], progress=False),
        "certify_stack": lambda: certify_stack(CAMS[None], PTS[None]),
    }
    model, truth = synthetic_model(n_points=6, noise_px=0.5, seed=3)
    paths["retriangulate"] = lambda: retriangulate(model)
    write_binary_model(model, tmp_path / "in")
    (tmp_path / "p.json").write_text(json.dumps({"cameras": CAMS.tolist(), "regions": PTS.tolist()}))
    paths["solve"] = lambda: cli.main(["solve", str(tmp_path / "p.json")])
    paths["colmap"] = lambda: cli.main(["colmap", str(tmp_path / "in"), str(tmp_path / "out")])
    for name, call in paths.items():
        for opts in built(name, call):
            assert opts == DEFAULT_OPTIONS, (name, opts)
    capsys.readouterr()
    # `dataset` reads an Oxford sequence: its flags build the same object (no data needed to compare)
    for argv in (["dataset", "house"], ["solve", "x.json"], ["colmap", "a", "b"]):
        assert cli.options_from_args(cli.build_parser().parse_args(argv)) == DEFAULT_OPTIONS, argv
    assert RetriangulationOptions().solver == DEFAULT_OPTIONS
    assert DEFAULT_OPTIONS.method.value == "auto" and DEFAULT_OPTIONS.path.value == "auto"
    assert DEFAULT_OPTIONS.budget == TRIANGULATION_BUDGET


SOLVER_FLAG_ERRORS = [
    (["--delta", "3"], "--delta: delta must be an even integer >= 2, got 3"),
    (["--delta", "0"], "--delta: delta must be an even integer >= 2, got 0"),
    (["--max-delta", "1"], "--max-delta: max_delta must be an even integer >= 2, got 1"),
    (["--delta", "4", "--max-delta", "2"], "--max-delta: max_delta (2) must be >= delta (4)"),
    (["--time-limit", "-1"], "--time-limit: must be a positive number of seconds, got -1"),
    (["--memory-limit", "0"], "--memory-limit: must be a positive number of GiB, got 0"),
    (["--method", "newton"], "argument --method: invalid choice: 'newton'"),
]


@pytest.mark.parametrize("flags, expect", SOLVER_FLAG_ERRORS, ids=[" ".join(f) for f, _ in SOLVER_FLAG_ERRORS])
def test_solver_flags_are_refused_alike_by_solve_and_colmap(flags, expect, tmp_path, capsys):
    """#14: --delta 3 / 0, --max-delta 1, --delta 4 --max-delta 2 exited 0 (the same values in a file exited 2)
    and `colmap --delta 3` wrote a model with every point invalid.  Both commands now exit 2 with the same line,
    and colmap writes nothing."""
    from tritools.cli.app import main
    from tritools.io.colmap import write_text_model
    from tests.test_colmap import synthetic_model

    (tmp_path / "p.json").write_text(json.dumps({"cameras": CAMS.tolist(), "regions": PTS.tolist()}))
    write_text_model(synthetic_model(n_points=4, seed=1)[0], tmp_path / "in")
    lines = []
    for argv in (["solve", str(tmp_path / "p.json")], ["colmap", str(tmp_path / "in"), str(tmp_path / "out")]):
        assert main(argv + flags) == 2, argv
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and expect in err, (argv, err)
        lines.append(err)
    assert lines[0].replace("tritools solve", "tritools colmap").replace("error: solve:", "error: colmap:") \
        == lines[1]                                                               # argparse names its command
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- #15: logging, progress bars
def test_library_code_never_prints():
    """#15: `logging` instead of prints in library code (everything but the command line, tritools/cli)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    offenders = []
    for package in ("sospoly", "tritools"):
        for path in sorted((root / package).rglob("*.py")):
            if "cli" in path.relative_to(root / package).parts:
                continue
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Call):
                    f = node.func
                    if isinstance(f, ast.Name) and f.id == "print":
                        offenders.append(f"{path.relative_to(root)}:{node.lineno}: print")
                    if isinstance(f, ast.Attribute) and f.attr == "write" and isinstance(f.value, ast.Attribute) \
                            and f.value.attr in ("stdout", "stderr"):
                        offenders.append(f"{path.relative_to(root)}:{node.lineno}: sys.{f.value.attr}.write")
    assert not offenders, offenders


def test_library_warnings_go_through_logging(caplog):
    """A skipped camera is reported by the library through `logging` (the CLI prints the summary)."""
    from tests.test_colmap import synthetic_model
    from tritools.io.colmap import Camera, Model
    from tritools.sfm import retriangulate

    model, truth = synthetic_model(n_points=6, noise_px=0.5, seed=3)
    cams = dict(model.cameras)
    cams[3] = Camera(3, "PINHOLE", 640, 480, (0.0, 800.0, 320.0, 240.0))
    with caplog.at_level("WARNING", logger="tritools"):
        retriangulate(Model(cams, model.images, model.points3D), max_delta=2)
    assert any(r.name.startswith("tritools.") and "camera 3 (PINHOLE) skipped" in r.getMessage()
               for r in caplog.records)


def test_no_progress_bar_for_tiny_batches(capsys):
    """#15: a progress bar was shown even for one item.  By default (progress=None) there is none below the
    thresholds, on every batch path; the thresholds are the documented ones."""
    from tests.test_colmap import synthetic_model
    from tritools.sfm import retriangulate
    from tritools.sfm.retriangulate import PROGRESS_MIN_POINTS, progress_bar
    from tritools.solve.batch import PROGRESS_MIN_ITEMS, _progress_bar

    tritools.triangulate_many([(CAMS, PTS)])
    tritools.triangulate_points(CAMS, PTS[None])
    retriangulate(synthetic_model(n_points=4, seed=1)[0], max_delta=2)
    assert capsys.readouterr().err == ""
    assert _progress_bar(1, "auto") is None and _progress_bar(PROGRESS_MIN_ITEMS - 1, "auto") is None
    assert progress_bar(1, "auto") is None and progress_bar(PROGRESS_MIN_POINTS - 1, "auto") is None
    assert progress_bar(None, "auto") is None and progress_bar(10 ** 6, False) is None
    assert _progress_bar(10 ** 6, None) is None and progress_bar(10 ** 6, None) is None   # library: only if asked
    pytest.importorskip("tqdm", reason="tqdm not installed (pip install '.[progress]')")
    import importlib

    retri = importlib.import_module("tritools.sfm.retriangulate")
    assert progress_bar(PROGRESS_MIN_POINTS, "auto") is None      # (the command line's bar: a terminal only)
    assert _progress_bar(PROGRESS_MIN_ITEMS, "auto") is None      # `tritools solve 2> log`: no bar (33a L10)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(retri, "stderr_is_terminal", lambda: True)
        mp.setattr(importlib.import_module("tritools.solve.batch"), "stderr_is_terminal", lambda: True)
        for bar in (_progress_bar(PROGRESS_MIN_ITEMS, "auto"), progress_bar(PROGRESS_MIN_POINTS, "auto"),
                    progress_bar(3, True)):
            assert bar is not None
            bar.close()
    capsys.readouterr()


# ----------------------------------------------------------------------------- #15: arrays in
def test_arrays_api_agrees_with_the_object_api():
    """#15: `triangulate(P, points_array)` raised "regions[0] must be a tritools Region" and `triangulate_many` with
    ndarray regions returned all invalid_input; `triangulate_points` (M points x V views, a visibility mask, like
    cv2.triangulatePoints) returns arrays that agree with the result objects of the other entry points."""
    from tritools.scene import random_scene

    sc = random_scene(4, 6, noise_px=1.0, seed=5)
    x = np.array(sc.points2d, float)                          # (M, V, 2)
    visible = np.ones(x.shape[:2], bool)
    visible[0, 3] = visible[2, 0] = visible[2, 1] = False     # points seen by 3, 4 and 2 views
    x[0, 3] = np.nan                                          # an unseen entry may hold anything
    res = tritools.triangulate_points(sc.cameras, x, visible, progress=False)
    assert len(res) == 6 and list(res.n_views) == [3, 4, 2, 4, 4, 4]
    objects = res.results()
    many = tritools.triangulate_many([(sc.cameras[v], x[m, v]) for m, v in enumerate(visible)], progress=False)
    for m, (o, r) in enumerate(zip(objects, many)):
        single = tritools.triangulate(sc.cameras[visible[m]], x[m, visible[m]])      # an (N, 2) array of points
        for other in (r, single):
            assert other.status == o.status and o.status.value == res.status[m]
            np.testing.assert_allclose(other.X, o.X, rtol=1e-6, atol=1e-9)
            assert other.gamma_ub == pytest.approx(o.gamma_ub, rel=1e-6)
        np.testing.assert_array_equal(res.X[m], o.X)
        assert (res.gamma_lb[m], res.gamma_ub[m], res.optimal[m], res.in_front[m]) == \
            (o.gamma_lb, o.gamma_ub, o.optimal, o.in_front)
        assert o.residuals.shape == (int(res.n_views[m]),)                          # per-view residuals
        np.testing.assert_allclose(o.residuals, single.residuals, rtol=1e-6, atol=1e-9)
    assert all(res.optimal)
    one_view = visible.copy()
    one_view[1] = [True, False, False, False]
    cut = tritools.triangulate_points(sc.cameras, x, one_view, progress=False)   # review 18: a row, not a raise
    assert cut.status[1] == tritools.Status.INVALID_INPUT and "points2d[1] is visible in fewer than 2 views" in \
        cut.message[1] and not cut.optimal[1]
    others = np.arange(len(x)) != 1
    np.testing.assert_array_equal(cut.X[others], res.X[others])
    assert list(cut.status[others]) == list(res.status[others])


# ----------------------------------------------------------------------------- #14: COLMAP diagnoses
def test_colmap_text_camera_with_focal_0_is_named_with_file_and_line(tmp_path, capsys):
    """#14: a COLMAP camera with focal 0 was diagnosed "x must be finite" and one bad camera aborted the whole
    model without file:line.  Now its observations are skipped with cameras.txt:LINE named (the binary twin is
    tests/test_colmap_cli.py::test_cameras_are_skipped_or_refused_with_strict), or, with --strict, exit 2."""
    from tests.test_colmap import synthetic_model
    from tritools.cli.app import main
    from tritools.io.colmap import Camera, Model, write_text_model

    model, _ = synthetic_model(n_points=10, noise_px=0.5, seed=3)
    cams = dict(model.cameras)
    cams[3] = Camera(3, "PINHOLE", 640, 480, (0.0, 800.0, 320.0, 240.0))
    write_text_model(Model(cams, model.images, model.points3D), tmp_path / "in")
    line = 1 + (tmp_path / "in" / "cameras.txt").read_text().splitlines().index("3 PINHOLE 640 480 0.0 800.0 320.0 "
                                                                                "240.0")
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "o"), "--json", "--max-delta", "2"]) == 3  # written,
    # with exit 3: observations were left out (tritools.cli.colmap.EXIT_CAMERAS_SKIPPED)
    (skip,) = json.loads(capsys.readouterr().out)["skipped_cameras"]
    assert skip["reason"] == f"cameras.txt:{line}: focal length fx = 0.0 must be > 0"
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "o2"), "--strict"]) == 2
    err = capsys.readouterr().err
    assert err == f"tritools: error: cameras.txt:{line}: camera 3 (PINHOLE) cannot be used: focal length fx = 0.0 " \
                  "must be > 0\n"
    assert "finite" not in err and not (tmp_path / "o2").exists()


def test_colmap_escalation_is_bounded_per_point(tmp_path, capsys):
    """#14: `tritools colmap` with defaults ran 10 minutes at 11 GB on a 2,000-point model because two points went
    to dense delta = 4 (one 7-view point: 242 s, 4.1 GB).  Every point that goes beyond the vectorised paths now
    runs under the per-point budget of `tritools solve` (--time-limit, --memory-limit): a limit too small for any
    certificate gives each point status time_limit at once, exit 0; each still carries its local L2 estimate
    (#23: every status has an estimate), written where it is no worse than the input (nearer the truth here)."""
    from tests.test_colmap import synthetic_model
    from tritools.cli.app import main
    from tritools.io.colmap import read_model, write_binary_model

    model, truth = synthetic_model(n_points=6, noise_px=0.5, seed=3)
    write_binary_model(model, tmp_path / "in")
    out, elapsed = _timed(lambda: main(["colmap", str(tmp_path / "in"), str(tmp_path / "o"), "--delta", "4",
                                        "--time-limit", "0.001", "--json"]))
    assert out == 0 and elapsed < 30
    summary = json.loads(capsys.readouterr().out)
    assert summary["status"] == {"time_limit": 6} and summary["time_limit"] == 0.001
    written = read_model(tmp_path / "o").points3D
    assert written.keys() == model.points3D.keys()
    for pid, p in written.items():
        assert p.track == model.points3D[pid].track
        assert np.linalg.norm(np.subtract(p.xyz, truth[pid])) <= np.linalg.norm(np.subtract(model.points3D[pid].xyz,
                                                                                            truth[pid])) + 1e-12
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "o4"), "--delta", "4", "--json"]) == 0
    points = json.loads(capsys.readouterr().out)["points"]
    assert all(p["status"] == "optimal" and p["delta"] == 4 for p in points)
