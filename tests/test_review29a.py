"""Review 29a (independent: long tracks and large batches) -- the fixes, each against an independent reference.

F3: rows of a batch cut by ``total_time_limit`` (:func:`tritools.solve.call_limit.expired_points`) reported a gamma_UB
below the exact gamma at their own float X in georeferenced worlds: each camera was divided by its largest entry,
which rounds every entry, and the world's offset amplifies that past gamma_UB's margin.  The reference here is
exact rational arithmetic on the caller's float data."""
from fractions import Fraction

import numpy as np
import pytest

import tritools
from tritools.solve.call_limit import expired_points
from tritools.solve.options import TriangulationOptions


def _camera(centre, target, f=800.0):
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]])
    return K @ np.hstack([R, (-R @ centre)[:, None]])


def _geo_track(N: int, seed: int, offset: float):
    """N cameras around the origin looking at it, moved into a world offset by ``offset`` metres."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(N, 3))
    C = 6 * v / np.linalg.norm(v, axis=1)[:, None]
    X = rng.normal(scale=0.3, size=3)
    cams = np.array([_camera(c, np.zeros(3)) for c in C])
    x = np.array([P[:2] @ np.append(X, 1) / (P[2] @ np.append(X, 1)) for P in cams]) + rng.normal(size=(N, 2))
    shift = np.eye(4)
    shift[:3, 3] = -offset
    return cams @ shift, x


def exact_f(cams, x, X) -> Fraction:
    """sum_i |pi(P_i (X, 1)) - x_i|^2 in exact rational arithmetic on the float data."""
    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    total = Fraction(0)
    for P, xi in zip(cams, x):
        h = [sum(Fraction(float(P[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
        total += sum((h[r] / h[2] - Fraction(float(xi[r]))) ** 2 for r in range(2))
    return total


def _assert_upper(cams, x, r):
    assert r.X is not None and r.gamma_ub is not None, r.message
    N = len(cams)
    assert Fraction(r.gamma_ub) ** 2 * (2 * N) >= exact_f(cams, x, r.X), (r.gamma_ub, N)


@pytest.mark.parametrize("offset", [5e8, 6e8, 1e9])
def test_expired_rows_bound_the_exact_gamma_in_georeferenced_worlds(offset):
    problems = [_geo_track(N, seed, offset) for seed, N in enumerate((3, 4, 5, 6, 15) * 2)]
    opts = TriangulationOptions()
    for cams, x in problems:           # one stack per view count, as the batch forms them
        r = expired_points(cams[None], x[None], opts)[0]
        assert r.status == "time_limit"
        _assert_upper(cams, x, r)


def test_a_batch_cut_by_its_whole_call_limit_keeps_valid_upper_bounds():
    problems = [_geo_track(N, 100 + seed, 6e8) for seed, N in enumerate((3, 4, 5, 6, 15, 30) * 3)]
    res = tritools.triangulate_many(problems, total_time_limit=1e-6, progress=False)
    assert len(res) == len(problems)
    for (cams, x), r in zip(problems, res):
        assert r.status == "time_limit" and not r.optimal
        _assert_upper(cams, x, r)


# ------------------------------------------------------------------------------------------------ F4: total_time_limit
# A robust batch under ``total_time_limit`` ran 1.4-1.9x its limit: the drive's searches counted their time limit from
# the drive's start (after the enumeration of their chunk), and the rows of the problems past the end (an L2
# refinement of up to 100 iterations each) came on top.  The checks here are on the deadlines each step is given, not
# on wall-clock times.
def _wrong_match_tracks(n_problems: int, seed: int = 7):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n_problems):
        N = int(rng.choice([3, 5, 8, 12, 20]))
        cams, x = _geo_track(N, 1000 + k, 0.0)
        x = x.copy()
        x[rng.choice(N, size=max(1, N // 4), replace=False)] += rng.uniform(40, 300, (max(1, N // 4), 2))
        out.append((cams, x))
    return out


def test_reserve_rules():
    import time

    from tritools.solve.call_limit import EXPIRED_SECONDS, RESERVE_TOP_SHARE, reserve_for, reserved_end
    a, b = EXPIRED_SECONDS
    assert reserve_for([3, 100]) == pytest.approx(2 * a + 103 * b)
    assert reserve_for([]) == 0.0
    assert reserved_end(None, 5.0) is None
    end = time.time() + 10.0
    assert reserved_end(end, 0.0) == end
    assert reserved_end(end, 1.0) == pytest.approx(end - 1.0)
    assert end - reserved_end(end, 100.0) <= RESERVE_TOP_SHARE * 10.0 + 1e-6      # never more than its share


def test_drive_searches_end_no_later_than_the_call(monkeypatch):
    import time

    from tritools.solve import robust as robust_mod
    from tritools.solve.call_limit import current_end
    seen = []
    original = robust_mod.TlsSearch.set_deadline

    def spy(self, deadline):
        end = current_end()
        if end is not None and deadline.end is not None:
            wall = time.time()                    # wall clock first: a pause between the two reads can only
            seen.append(deadline.end - (time.monotonic() + (end - wall)))      # lower the value checked
        return original(self, deadline)

    monkeypatch.setattr(robust_mod.TlsSearch, "set_deadline", spy)
    problems = _wrong_match_tracks(120)
    res = tritools.triangulate_many(problems, robust=6.0, time_limit=100.0, total_time_limit=30.0,
                                  progress=False)
    assert len(res) == len(problems)
    assert seen, "no search of the drive was given a deadline"
    assert max(seen) <= 2e-3, max(seen)       # no search's deadline after the end of its call's scope


def test_batch_steps_keep_a_reserve_for_the_later_rows(monkeypatch):
    """The point stacks of a batch run in a scope that ends before the call's end by the reserve of the problems
    after them, and the later stacks get the rest."""
    import time

    from tritools.solve import batch as batch_mod
    from tritools.solve.call_limit import current_end, reserve_for
    ends = []
    Original = batch_mod.PointStack

    class Spy(Original):
        def run(self):
            ends.append((len(self.x) if hasattr(self, "x") else None, current_end()))
            return super().run()

    monkeypatch.setattr(batch_mod, "PointStack", Spy)
    problems = [_geo_track(3, s, 0.0) for s in range(40)] + [_geo_track(30, 100 + s, 0.0) for s in range(40)]
    t0 = time.time()
    res = tritools.triangulate_many(problems, total_time_limit=60.0, progress=False)
    assert len(res) == len(problems) and len(ends) == 2
    first, second = ends[0][1], ends[1][1]        # the second stack ends at the call's end (less a few open rows')
    assert t0 + 60.0 - 1.0 < second <= time.time() + 60.0
    assert first <= second - 0.9 * reserve_for([30] * 40)         # the 30-view stack's rows are kept time for


# --------------------------------------------------------------------------------- F2: estimates of uncertified points
# A 100-view track with 20% wrong matches, its point 1 cm from a camera's centre: the dense degree-2 program is
# refused by the memory estimate (``budget_exceeded``) and the estimate was the local refinement of the DLT point,
# gamma_UB 1106 px where least squares from the planted point reaches 80.8 px.  Reference: scipy's least_squares.
def _near_centre_track(N: int, seed: int, near: float = 1e-2, frac: float = 0.2):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(N, 3))
    C = 6 * v / np.linalg.norm(v, axis=1)[:, None]
    X = C[0] - near * C[0] / np.linalg.norm(C[0])
    cams = np.array([_camera(c, np.zeros(3)) for c in C])
    x = np.array([P[:2] @ np.append(X, 1) / (P[2] @ np.append(X, 1)) for P in cams]) + rng.normal(size=(N, 2))
    k = int(frac * N)
    idx = rng.choice(np.arange(1, N), k, replace=False)
    x[idx] += rng.uniform(30, 300, (k, 2)) * rng.choice([-1, 1], (k, 2))
    return cams, x, X


def _least_squares_gamma(cams, x, X0) -> float:
    from scipy.optimize import least_squares

    def res(X):
        h = cams @ np.append(X, 1.0)
        return (h[:, :2] / h[:, 2:] - x).ravel()

    r = least_squares(res, X0, method="lm", xtol=1e-15, ftol=1e-15)
    return float(np.sqrt(r.fun @ r.fun / (2 * len(cams))))


def test_an_uncertified_long_track_gets_the_multistart_estimate():
    cams, x, X_true = _near_centre_track(100, 1)
    ref = _least_squares_gamma(cams, x, X_true)
    r = tritools.triangulate(cams, x)
    assert not r.optimal
    assert r.gamma_ub <= ref * (1 + 1e-6), (r.gamma_ub, ref)
    assert r.gamma_lb is None or r.gamma_lb <= r.gamma_ub
    assert Fraction(r.gamma_ub) ** 2 * 200 >= exact_f(cams, x, r.X)          # still an upper bound at its X
    (b,) = tritools.triangulate_many([(cams, x)], progress=False)
    assert b.status == r.status and b.gamma_ub == pytest.approx(r.gamma_ub, rel=1e-9)


def test_multistart_pairs_are_fixed_and_distinct():
    from tritools.solve.multistart import MULTISTART_PAIRS, pair_sample

    assert pair_sample(3).tolist() == [[0, 1], [0, 2], [1, 2]]
    p = pair_sample(300)
    assert p.shape == (MULTISTART_PAIRS, 2) and np.all(p[:, 0] != p[:, 1]) and np.all((0 <= p) & (p < 300))
    assert np.array_equal(p, pair_sample(300))


# ------------------------------------------------------------------------ F6: time charged to a search in a batch
# The drive split a round's batched calls evenly: a disc problem certified alone in 0.3 s paid for the other
# problems' region sub-problems (solved one by one, seconds each) and stopped at its time limit in a batch.
def test_a_round_charges_each_search_its_own_sub_problems():
    from tritools.solve.robust_drive import charges

    assert charges(3.0, []) == []
    assert charges(3.0, [0.0, 0.0, 0.0]) == pytest.approx([2.0, 2.0, 2.0])      # the even split, as before
    waited = charges(3.0, [2.7, 0.0, 0.0])      # 2.7 s of the round were search 0's own region solves
    assert waited[1] == pytest.approx(2.9) and waited[2] == pytest.approx(2.9) and waited[0] == pytest.approx(0.2)
    assert all(w >= 0 for w in charges(1.0, [0.8, 0.8]))                       # clocks never move back


def test_compute_many_reports_the_seconds_of_its_one_by_one_solves():
    from tritools.model.regions import Ellipse
    from tritools.solve.robust_bounds import compute_many

    cams, x = _geo_track(5, 3, 0.0)
    regions = [Ellipse(p, np.eye(2)) for p in x]
    from tritools.solve.options import TriangulationOptions
    from tritools.solve.robust_bounds import SubsetBounds

    sb = SubsetBounds(cams, tuple(regions), TriangulationOptions(), TriangulationOptions().budget.deadline(),
                      points=False)
    solved = compute_many([(sb, [frozenset(range(5)), frozenset({0, 1, 2})])])
    assert set(solved) == {id(sb)} and solved[id(sb)] > 0


def test_each_chunk_keeps_the_reserve_of_the_chunks_after_it():
    """The reserve of a per-item chunk covered only its own later items: its last item ran to the end and every later
    chunk started expired (the diff review of this wave)."""
    from tritools.solve.batch import _after_seconds
    from tritools.solve.call_limit import reserve_for

    item = (0, None, [None] * 10, None, ())
    chunks = [[item] * 8, [item] * 8, [item] * 4]
    one = reserve_for([10])
    assert _after_seconds(chunks, 1) == pytest.approx([12 * one, 4 * one, 0.0])
    assert _after_seconds(chunks, 2) == pytest.approx([6 * one, 2 * one, 0.0])      # shared by two workers
