"""Issue #18 items 5-6: one options class (the SfM options compose TriangulationOptions), the structured
OptionError, one Sparsity enum, one default time limit, and the whole-call limit ``total_time_limit``."""
import dataclasses
from types import SimpleNamespace
import json
import pickle
import time

import numpy as np
import pytest

import sospoly
import tritools
from tests.cli_util import run, write
from tritools.scene import paper_example
from tritools.sfm import CertifyOptions, OptionError, RetriangulationOptions
from tritools.solve.call_limit import CUT_MESSAGE
from tritools.solve.options import DEFAULT_OPTIONS, OptionTypeError, TriangulationOptions


def rms_reprojection(X, cameras, points):
    """gamma(X) (SPEC section 1) written out with numpy: the RMS over the 2N coordinates of the residuals."""
    h = np.asarray(cameras) @ np.append(X, 1.0)
    r = h[:, :2] / h[:, 2:3] - np.asarray(points)
    return float(np.sqrt(np.sum(r ** 2) / (2 * len(points))))


# ----------------------------------------------------------------------------- OptionError
@pytest.mark.parametrize("kw, field, reason, text", [
    ({"delta": 3}, "delta", "must be an even integer >= 2, got 3", "delta must be an even integer >= 2, got 3"),
    ({"delta": 4, "max_delta": 2}, "max_delta", "must be >= delta (4), got 2", "max_delta (2) must be >= delta (4)"),
    ({"delta": 2000}, "delta", "must be at most 1000, got 2000", "delta = 2000 is far beyond"),
    ({"method": "nms"}, "method", "must be one of", "method must be one of"),
    ({"sparsity": "cliquey"}, "sparsity", "must be one of 'auto', 'none' (or 'dense'), 'views' (or 'cliques')",
     "sparsity must be one of"),
    ({"world_frame": "left"}, "world_frame", "world_frame must be one of", "world_frame must be one of"),
    ({"total_time_limit": -1}, "total_time_limit", "must be a positive number", "total_time_limit must be"),
    ({"total_time_limit": float("nan")}, "total_time_limit", "must be a positive number", "total_time_limit"),
])
def test_every_check_names_its_field(kw, field, reason, text):
    with pytest.raises(OptionError) as exc:
        TriangulationOptions(**kw)
    assert isinstance(exc.value, ValueError) and exc.value.field == field
    assert reason in exc.value.reason and text in str(exc.value)


def test_type_errors_are_option_errors_too_and_pickle():
    for kw, field in (({"refine": 1.5}, "refine"), ({"budget": 3}, "budget"), ({"tolerances": "tight"}, "tolerances")):
        with pytest.raises(TypeError) as exc:
            TriangulationOptions(**kw)
        assert isinstance(exc.value, OptionTypeError) and exc.value.field == field
    with pytest.raises(OptionError) as exc:
        DEFAULT_OPTIONS.replace(time_limit=-1)
    assert exc.value.field == "time_limit"
    with pytest.raises(TypeError) as exc:
        DEFAULT_OPTIONS.replace(colour="red")
    assert exc.value.field == "colour"
    err = pickle.loads(pickle.dumps(OptionError("max_delta", "must be >= delta (4), got 2", "max_delta (2) ...")))
    assert (err.field, err.reason, str(err)) == ("max_delta", "must be >= delta (4), got 2", "max_delta (2) ...")
    assert tritools.sfm.OptionError is OptionError is tritools.solve.options.OptionError


# ----------------------------------------------------------------------------- composition
def test_sfm_options_hold_one_triangulation_options():
    base = DEFAULT_OPTIONS.replace(time_limit=7, sparsity="views")
    r = RetriangulationOptions(solver=base, method="corollary1", max_delta=2, chunk_points=5)
    assert r.solver == base.replace(method="corollary1", max_delta=2)
    assert (r.method, r.path, r.delta, r.max_delta) == ("corollary1", "auto", None, 2)
    assert r.solver.budget.time_limit == 7 and r.solver.sparsity is sospoly.Sparsity.CLIQUES
    assert "method" not in {f.name for f in dataclasses.fields(r)}          # not re-declared: read from solver
    pool = SimpleNamespace(submit=lambda *a: None)                  # (any object with submit(), checked)
    again = dataclasses.replace(r, executor=pool)
    assert again == r and again.executor is pool and again.chunk_points == 5
    c = r.certify_options()
    assert c.triangulation_options() is r.solver and c == CertifyOptions(options=r.solver)
    assert CertifyOptions(delta=4).options == DEFAULT_OPTIONS.replace(delta=4)
    with pytest.raises(OptionError) as exc:
        RetriangulationOptions(solver=base.replace(delta=4), max_delta=2)      # checked once, by the options
    assert exc.value.field == "max_delta" and exc.value.detail == "must be >= delta (4), got 2"
    with pytest.raises(TypeError) as exc:
        CertifyOptions(options="fast")
    assert exc.value.field == "options"


# ----------------------------------------------------------------------------- sparsity, time limit
def test_one_sparsity_enum_for_both_packages():
    S = sospoly.Sparsity
    assert S("none") is S.DENSE is S.NONE and S("dense") is S.DENSE and str(S.TERM) == "term"
    assert tritools.Sparsity is S
    assert TriangulationOptions(sparsity="none").sparsity is S.DENSE
    assert TriangulationOptions(sparsity="dense").sparsity is S.DENSE
    assert TriangulationOptions(sparsity="views").sparsity is S.CLIQUES
    x, y = sospoly.variables("x y")
    f = (x - 1) ** 2 + (y + 2) ** 2 + x * y
    a = sospoly.minimize(f, degree=2, sparsity="none")
    b = sospoly.minimize(f, degree=2, sparsity=S.DENSE)
    assert a.sparsity == b.sparsity == "dense" and a.n_lmivar == b.n_lmivar
    assert abs(a.lower_bound - b.lower_bound) <= 1e-9 * (1 + abs(a.lower_bound))
    with pytest.raises(ValueError, match="sparsity must be one of"):
        sospoly.minimize(f, degree=2, sparsity="cliques")            # caller-given cliques: not a minimize choice
    assert not hasattr(sospoly.certificates.shape, "chain_cliques")


def test_one_default_time_limit():
    assert sospoly.Budget().time_limit == sospoly.DEFAULT_TIME_LIMIT == DEFAULT_OPTIONS.budget.time_limit == 60.0
    assert DEFAULT_OPTIONS.total_time_limit is None


# ----------------------------------------------------------------------------- the whole-call limit
def test_expired_call_gives_every_point_a_row_with_its_estimate():
    cams, pts = paper_example(4)
    x = np.array([r.x for r in pts])
    probs = [(cams, pts)] * 40 + [(cams, x + 0.5)] * 3
    t0 = time.perf_counter()
    out = tritools.triangulate_many(probs, total_time_limit=1e-9)
    assert time.perf_counter() - t0 < 20
    assert len(out) == len(probs)
    for (C, p), r in zip(probs, out):
        p = np.array([q.x for q in p]) if isinstance(p, (list, tuple)) else p
        assert r.status == tritools.Status.TIME_LIMIT and not r.optimal and r.gamma_lb is None
        assert r.X is not None and CUT_MESSAGE in r.message
        assert r.gamma_ub == pytest.approx(rms_reprojection(r.X, C, p), rel=1e-9)   # gamma at X: an upper bound
    free = tritools.triangulate_many(probs[:2])
    assert all(r.optimal for r in free)
    assert all(r.gamma_lb <= f.gamma_ub * (1 + 1e-6) for r, f in zip(free, out[:2]))    # never below gamma*


@pytest.mark.slow
def test_whole_call_limit_bounds_a_batch_of_sdps():
    """Ellipse regions go through the per-point SDP path: 30 of them take ~0.3-3 s unbounded (~10-100 ms each,
    by machine load); with total_time_limit = 0.03 s the call ends soon after, every row present, certified rows
    still valid."""
    cams, _ = paper_example(4)
    rng = np.random.default_rng(3)
    probs = []
    for _ in range(30):
        X = rng.normal(size=3)
        h = cams @ np.append(X, 1.0)
        x = h[:, :2] / h[:, 2:3] + rng.normal(scale=0.05, size=(len(cams), 2))
        probs.append((cams, [tritools.Ellipse(c, np.eye(2) * 1e-6) for c in x]))
    t0 = time.perf_counter()
    out = tritools.triangulate_many(probs, total_time_limit=0.03, path="sdp", method="theorem1", executor=None)
    took = time.perf_counter() - t0
    assert len(out) == 30 and took < 15, took
    assert any(r.status == tritools.Status.TIME_LIMIT for r in out)
    for r in out:
        assert r.status != tritools.Status.SOLVER_FAILED and r.X is not None
        if r.gamma_lb is not None:
            assert r.gamma_lb <= r.gamma_ub * (1 + 1e-9)


def test_robust_batches_take_the_whole_call_limit():
    """TLS searches cut by the whole-call limit keep valid bounds (gamma_LB <= the certified TLS optimum)."""
    cams, pts = paper_example(4)
    x = np.array([p.x for p in pts])
    x[1] += 3.0                                               # one gross outlier
    cut = tritools.triangulate_many([(cams, x)] * 4, robust=1.0, total_time_limit=1e-9)
    full = tritools.triangulate_many([(cams, x)], robust=1.0)[0]
    assert full.optimal
    for r in cut:
        assert r.status == tritools.Status.TIME_LIMIT and CUT_MESSAGE in r.message and r.X is not None
        assert r.gamma_lb <= full.gamma_ub * (1 + 1e-9) and full.gamma_lb <= r.gamma_ub * (1 + 1e-9)


def test_triangulate_points_and_cli_take_the_whole_call_limit(tmp_path, capsys):
    cams, pts = paper_example(4)
    x = np.array([r.x for r in pts])
    res = tritools.triangulate_points(cams, np.stack([x, x + 1.0, x - 2.0]), total_time_limit=1e-9)
    assert list(res.status) == ["time_limit"] * 3 and np.all(np.isfinite(res.X))
    doc = {"problems": [{"cameras": np.asarray(cams).tolist(), "regions": x.tolist()}] * 3}
    rc, out, err = run(["solve", write(tmp_path, doc), "--total-time-limit", "1e-9", "--json"], capsys)
    rows = json.loads(out)
    assert rc == 0 and [r["status"] for r in rows] == ["time_limit"] * 3 and all(r["X"] for r in rows)
    rc, out, err = run(["solve", write(tmp_path, doc), "--total-time-limit", "-1"], capsys)
    assert rc == 2 and err.count("\n") == 1 and "--total-time-limit: must be a positive number of seconds" in err


def test_colmap_workflow_takes_the_whole_call_limit(tmp_path):
    from tests.test_colmap import synthetic_model
    from tritools.io.colmap import write_text_model
    from tritools.sfm import retriangulate, retriangulate_folder

    model, _ = synthetic_model(n_points=10, seed=2)
    new, report = retriangulate(model, solver=DEFAULT_OPTIONS.replace(total_time_limit=1e-9))
    assert len(report.records) == 10
    assert {r.status.value for r in report.records} == {"time_limit"} and not any(r.certified for r in report.records)
    new, report = retriangulate(model)
    assert all(r.certified for r in report.records)
    write_text_model(model, tmp_path / "in")
    cut = RetriangulationOptions(solver=DEFAULT_OPTIONS.replace(total_time_limit=1e-9))
    res = retriangulate_folder(tmp_path / "in", tmp_path / "out", cut)
    assert [r.status.value for r in res.report.records] == ["time_limit"] * 10
    assert retriangulate_folder(tmp_path / "in", tmp_path / "out2").report.n_certified == 10
