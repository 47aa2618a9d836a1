"""The one result record (issue #18 item 2): tritools.records.TriangulationResults, a column-oriented Sequence
whose rows are TriangulationResult -- round trips, one JSON form, the entry points that produce it, bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest

import tritools
from tritools import Attempt, Status, TriangulationResult, TriangulationResults
from tritools.scene import random_scene


def _rows():
    """Rows of every shape a batch meets: certified with per-view arrays, a failure without any, a baseline
    (optimal None), a robust row with inliers, NaN / infinite values."""
    return [
        TriangulationResult("corollary1", Status.OPTIMAL, X=[1.0, 2.0, 3.0], gamma_ub=0.5, gamma_lb=0.4999,
                            optimal=True, delta=2, n_lmivar=10, image_points=np.arange(6.0).reshape(3, 2),
                            X_raw=[1.0, 2.0, 3.1], gamma_ub_raw=0.6, certified_by="verification", message="",
                            timings={"total": 0.25},
                            attempts=(Attempt("corollary1", 2, "verified", 0.4999, None, "verification", "dense"),),
                            sparsity="dense", in_front=True, depths=[1.0, 2.0, 3.0], residuals=[0.1, 0.2, 0.3]),
        TriangulationResult("auto", "invalid_input", message="ValueError: cameras must be (N, 3, 4)"),
        TriangulationResult("dlt", Status.NO_CERTIFICATE, X=[0.0, 0.0, 1.0], gamma_ub=np.inf, in_front=False,
                            depths=[-1.0, 2.0], residuals=[np.inf, 0.0], timings={"total": 1e-3}),
        TriangulationResult("tls", Status.NOT_CERTIFIED, X=[0.5, 0.5, 5.0], gamma_ub=2.0, gamma_lb=1.0, optimal=False,
                            delta=4, inliers=[True, False, True, True], residuals=[0.1, 9.0, 0.2, 0.3],
                            timings={"batch_share": 0.5}, in_front=True),
    ]


def _same_rows(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.to_dict() == y.to_dict()


def test_rows_to_table_to_rows_is_exact():
    rows = _rows()
    t = TriangulationResults.from_rows(rows)
    assert len(t) == 4 and list(t.n_views) == [3, 0, 2, 4] and t.width == 4
    _same_rows(list(t), rows)
    assert t == rows and all(t[i] == rows[i] for i in range(4)) and t[-1] == rows[-1]
    # None survives where a column cannot hold it: optimal of the baseline, per-view arrays of the failure
    assert t[2].optimal is None and t[1].X is None and t[1].residuals is None and t[0].inliers is None
    assert t[2].gamma_lb is None and t[2].gamma_ub == np.inf and t[3].delta == 4 and t[1].delta is None
    assert t[0].attempts == rows[0].attempts and t[3].timings == {"batch_share": 0.5}


def test_columns_are_the_rows_values():
    rows = _rows()
    t = TriangulationResults.from_rows(rows)
    assert t.X.shape == (4, 3) and t.status.dtype == object and all(isinstance(s, Status) for s in t.status)
    np.testing.assert_array_equal(t.gamma_ub, [0.5, np.nan, np.inf, 2.0])
    np.testing.assert_array_equal(t.optimal, [True, False, False, False])
    np.testing.assert_array_equal(t.delta, [2, -1, -1, 4])
    np.testing.assert_array_equal(t.certified, [True, False, False, False])
    assert list(t.status) == ["optimal", "invalid_input", "no_certificate", "not_certified"]   # Status is a str
    np.testing.assert_array_equal(t.inliers[3], [True, False, True, True])
    np.testing.assert_array_equal(t.timings["total"], [0.25, np.nan, 1e-3, np.nan])
    with pytest.raises(ValueError):
        t.gamma_ub[0] = 0.0                                   # columns are read-only: the record is frozen


def test_one_json_form_round_trip():
    rows = _rows()
    t = TriangulationResults.from_rows(rows)
    d = json.loads(json.dumps(t.to_dict(), allow_nan=False))         # NaN / inf as null: strict JSON
    assert [r for r in d["results"]] == [json.loads(json.dumps(r.to_dict(), allow_nan=False)) for r in rows]
    back = TriangulationResults.from_dict(d)
    assert back == t and [back[i].to_dict() for i in range(4)] == [r.to_dict() for r in rows]
    # a row's JSON is the row of the table's; the table reads a bare list of rows too
    assert TriangulationResults.from_dict(d["results"]) == rows


def test_concat_take_and_slices_are_list_operations():
    rows = _rows()
    a, b = TriangulationResults.from_rows(rows[:2]), TriangulationResults.from_rows(rows[2:])
    c = TriangulationResults.concat([a, b])
    assert c == rows and c.width == 4
    assert c.take([3, 0]) == [rows[3], rows[0]]
    assert c.take(np.array([False, True, True, False])) == rows[1:3]
    assert c[1:3] == rows[1:3] and c[::-1] == rows[::-1] and c.take([]) == []
    assert TriangulationResults.concat([]) == [] and len(TriangulationResults.concat([c, c])) == 8
    assert c.drop("attempts", "depths")[0].attempts == () and c.drop("depths")[0].depths is None


def test_with_views_places_per_view_entries_in_their_slots():
    rows = _rows()
    t = TriangulationResults.from_rows(rows)
    views = np.array([[1, 1, 1, 0, 0], [0, 0, 0, 0, 0], [0, 1, 0, 0, 1], [1, 1, 0, 1, 1]], bool)
    v = t.with_views(views)
    assert v == rows and list(v.n_views) == [3, 0, 2, 4]
    np.testing.assert_array_equal(v.inliers[3], [True, False, False, True, True])     # False where not seen
    np.testing.assert_array_equal(v.residuals[2], [np.nan, np.inf, np.nan, np.nan, 0.0])
    assert TriangulationResults.from_dict(v.to_dict()) == v
    with pytest.raises(ValueError, match="views"):
        t.with_views(np.ones((4, 5), bool))                   # row 0 has 3 per-view entries, not 5


@pytest.mark.parametrize("kw, column", [
    (dict(status=["optimal", "great"]), "status"),
    (dict(X=np.zeros((3, 3))), "X"),
    (dict(gamma_ub=["a", "b"]), "gamma_ub"),
    (dict(gamma_lb=["1.0", "2.0"]), "gamma_lb"),
    (dict(n_lmivar=[True, False]), "n_lmivar"),
    (dict(optimal=[0.5, 1.0]), "optimal"),
    (dict(delta=[2.5, 2]), "delta"),
    (dict(method=["corollary1", 7]), "method"),
    (dict(certified_by=[3, None]), "certified_by"),
    (dict(n_views=[2, 2], residuals=np.zeros((2, 3)), views=np.ones((2, 3), bool)), "views"),
    (dict(n_views=[-1, 2]), "n_views"),
    (dict(null={"gamma_ub": [True, False]}), "null"),
    (dict(timings={"total": [1.0]}), "timings"),
    (dict(depths=np.zeros((2, 3, 2))), "depths"),
])
def test_bad_construction_names_the_column(kw, column):
    base = dict(method=["corollary1", "corollary1"], status=["optimal", "optimal"])
    with pytest.raises(ValueError, match=rf"TriangulationResults\.{column}"):
        TriangulationResults(**{**base, **kw})


def test_bad_rows_are_refused_by_name():
    rows = _rows()
    with pytest.raises(TypeError, match=r"rows\[1\]"):
        TriangulationResults.from_rows([rows[0], {"status": "optimal"}])
    odd = TriangulationResult("tls", Status.NOT_CERTIFIED, residuals=[1.0, 2.0], inliers=[True, False, True])
    with pytest.raises(ValueError, match=r"TriangulationResults\.inliers of rows\[0\] has 3 entries"):
        TriangulationResults.from_rows([odd])
    with pytest.raises(ValueError, match=r"TriangulationResults\.n_views"):
        TriangulationResults.from_rows(rows, n_views=[1, 2])
    with pytest.raises(TypeError, match="index"):
        TriangulationResults.from_rows(rows).take(np.array([0.5]))


def test_triangulate_many_returns_the_record_and_its_rows_are_the_results():
    sc = random_scene(3, 5, noise_px=1.0, seed=3)
    problems = [(sc.cameras, sc.regions(j)) for j in range(4)] + [("not", "a pair")]
    res = tritools.triangulate_many(problems, progress=False)
    assert isinstance(res, TriangulationResults) and len(res) == 5
    assert res[4].status == Status.INVALID_INPUT and res.status[4] == Status.INVALID_INPUT
    assert TriangulationResults.from_rows(list(res)) == res
    assert TriangulationResults.from_dict(json.loads(json.dumps(res.to_dict(), allow_nan=False))) == res
    for i in range(4):
        r = res[i]
        assert r == res.row(i) and r.status == res.status[i] and r.optimal == res.optimal[i]
        assert r.gamma_ub == res.gamma_ub[i] and np.array_equal(r.X, res.X[i])
        # gamma_ub is gamma(X) (paper eq. (6)), computed independently from the row's estimate
        assert abs(tritools.gamma(r.X[None], sc.cameras, sc.regions(i))[0] - r.gamma_ub) <= 1e-9 * max(1, r.gamma_ub)
        single = tritools.triangulate(sc.cameras, sc.regions(i))
        assert single.status == r.status and single.optimal == r.optimal
        np.testing.assert_allclose(single.X, r.X, rtol=1e-6, atol=1e-9)
        assert res.gamma_lb[i] <= res.gamma_ub[i]


def test_triangulate_points_is_the_record_with_the_visibility_as_views():
    sc = random_scene(4, 5, noise_px=1.0, seed=8)
    x = np.array(sc.points2d, float)
    visible = np.ones(x.shape[:2], bool)
    visible[1, 0] = visible[3, 2] = False
    pts = tritools.triangulate_points(sc.cameras, x, visible, progress=False)
    assert isinstance(pts, tritools.PointsResult) and isinstance(pts, TriangulationResults)
    np.testing.assert_array_equal(pts.views, visible)
    for m in range(len(pts)):
        r = pts[m]
        np.testing.assert_array_equal(pts.residuals[m, visible[m]], r.residuals)
        assert np.all(np.isnan(pts.residuals[m, ~visible[m]]))
        # residuals are the per-view distances of the row's estimate (computed here from the cameras)
        P = sc.cameras[visible[m]]
        h = P @ np.append(r.X, 1.0)
        np.testing.assert_allclose(np.hypot(*(h[:, :2] / h[:, 2:] - x[m, visible[m]]).T), r.residuals,
                                   rtol=1e-9, atol=1e-9)
    assert pts.results() == list(pts)


def test_sfm_results_carry_the_record():
    from tritools.sfm import certify_stack, retriangulate_arrays
    from tritools.sfm.certify import STATUS_LEGEND
    from tritools.sfm.synthetic import synthetic_arrays

    arrays, _ = synthetic_arrays(n_points=40, n_images=6, camera="PINHOLE", seed=9)
    _, report = retriangulate_arrays(arrays)
    assert isinstance(report.results, TriangulationResults) and len(report.results) == report.n_points
    for i, rec in enumerate(report.records):
        row = report.results[i]
        assert rec.result == row and rec.status == row.status and STATUS_LEGEND[report.status[i]] == row.status.value
        assert rec.gamma_ub == row.gamma_ub and rec.n_views == report.results.n_views[i]
    sc = random_scene(3, 4, noise_px=0.5, seed=2)
    s = certify_stack(np.broadcast_to(sc.cameras, (4,) + sc.cameras.shape), np.array(sc.points2d))
    many = tritools.triangulate_many([(sc.cameras, np.array(sc.points2d)[m]) for m in range(4)], progress=False)
    assert list(s.results.status) == list(many.status) and list(s.results.certified_by) == list(many.certified_by)
    np.testing.assert_allclose(s.results.X, many.X, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(s.gamma_ub, s.results.gamma_ub)
    assert [STATUS_LEGEND[k] for k in s.status] == [v.value for v in many.status]


def test_absent_columns_cost_no_memory_and_read_as_none():
    M = 10 ** 6
    t = TriangulationResults(method=["dlt"] * M, status=[Status.NO_CERTIFICATE] * M)
    for col in (t.X, t.gamma_lb, t.delta, t.optimal, t.attempts, t.certified_by):
        assert not any(col.strides)                            # one broadcast value, not M copies
    c = TriangulationResults.concat([t.take(np.arange(3)), t.take([5])])
    assert not any(c.X.strides) and len(c) == 4
    r = c[3]
    assert (r.X, r.gamma_lb, r.delta, r.optimal, r.attempts, r.certified_by) == (None, None, None, False, (), None)
    mixed = TriangulationResults.concat([c, TriangulationResults.from_rows(_rows()[:1])])
    assert mixed[0].X is None and mixed[4] == _rows()[0] and mixed[4].delta == 2


def test_replace_keeps_absent_columns_absent():
    import dataclasses

    t = TriangulationResults(method=["dlt"] * 5, status=["no_certificate"] * 5, gamma_ub=np.arange(5.0))
    r = dataclasses.replace(t, message=["a", "b", "c", "d", "e"])
    assert not any(r.X_raw.strides) and not any(r.attempts.strides) and r[4].message == "e"
    np.testing.assert_array_equal(r.gamma_ub, np.arange(5.0))
    const = TriangulationResults(method=["dlt"] * 3, status=["optimal"] * 3, delta=np.broadcast_to(4, (3,)))
    assert [x.delta for x in const] == [4, 4, 4]              # a constant column that is not the default stays


def test_an_empty_part_does_not_make_absent_columns_present():
    empty = TriangulationResults(method=[], status=[])
    t = TriangulationResults(method=["dlt"] * 2, status=["optimal"] * 2, gamma_ub=[1.0, 2.0])
    c = TriangulationResults.concat([empty, t])
    assert c == list(t) and not any(c.X_raw.strides) and not any(c.attempts.strides)
