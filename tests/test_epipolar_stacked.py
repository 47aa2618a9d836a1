"""The stacked epipolar constraints (issue #22): :func:`tritools.model.constraints.corollary1_constraints` gives the
polynomials (coefficients, term order) and the pair bookkeeping of the pair-by-pair reference below (the loop
over ``fundamental_matrix`` and polynomial arithmetic it replaced), and the stacked fundamental matrices are
``fundamental_matrix``'s to the bit."""
from __future__ import annotations

import numpy as np
import pytest

from sospoly import Polynomial, variables
from tritools.model.centres import dot_norms, pair_fundamentals, skew_stack
from tritools.model.constraints import (_pair_homography, centre_relations, corollary1_constraints,
                                        epipolar_polynomial)
from tritools.model.geometry import _skew, fundamental_matrix
from tritools.model.stacked import view_pairs


def _reference(cameras, gens, x_index, pairs=None, relations=None):
    """The loop the stacked constraints replaced (fundamental_matrix per pair, F / ||F||, arithmetic)."""
    gens = tuple(gens)
    n, N = len(gens), cameras.shape[0]
    pairs = [(i, j) for i in range(N) for j in range(i + 1, N)] if pairs is None else [tuple(p) for p in pairs]

    def var(k):
        e = [0] * n
        e[x_index[k]] = 1
        return Polynomial(gens, {tuple(e): 1.0})

    one = Polynomial.constant(1.0, gens)
    xt = [[var(2 * i), var(2 * i + 1), one] for i in range(N)]
    polys, kept, skipped, homography = [], [], [], []
    loose = relations.loose if relations is not None else frozenset()
    for i, j in pairs:
        if i in loose or j in loose:
            skipped.append((i, j))
            continue
        try:
            if relations is not None and relations.groups[i] == relations.groups[j]:
                raise ValueError("one centre (raw cameras)")
            F = fundamental_matrix(cameras[i], cameras[j])
        except ValueError:
            if relations is None:
                H = _pair_homography(cameras[i], cameras[j])
            else:
                H = _pair_homography(cameras[i], cameras[j], check=False) if (i, j) in relations.coincident \
                    else None
            if H is None:
                skipped.append((i, j))
                continue
            Hx = [sum((float(H[a, b]) * xt[i][b] for b in range(3) if H[a, b] != 0.0), Polynomial(gens, {}))
                  for a in range(3)]
            for a in range(3):
                b, c = (a + 1) % 3, (a + 2) % 3
                polys.append(xt[j][b] * Hx[c] - xt[j][c] * Hx[b])
                kept.append((i, j))
            homography.append((i, j))
            continue
        polys.append(epipolar_polynomial(gens, F / np.linalg.norm(F), xt[i], xt[j]))
        kept.append((i, j))
    return polys, {"N1": len(polys), "N2": len(polys), "pairs": kept, "skipped": skipped, "homography": homography}


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _cameras(rng, N: int, offset: float) -> np.ndarray:
    """Cameras with exactly repeated, nearly repeated (1e-17..1e-6) and distinct centres, rescaled 1e-3..1e6."""
    cs = [rng.normal(size=3) * 5 + offset]
    for _ in range(1, N):
        u = rng.random()
        c = cs[rng.integers(len(cs))]
        cs.append(c.copy() if u < 0.2 else c * (1 + 10.0 ** rng.uniform(-17, -6) * rng.normal(size=3)) if u < 0.3
                  else rng.normal(size=3) * 5 + offset)
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    C = np.array([K @ _rotation(rng) @ np.hstack([np.eye(3), -c[:, None]]) for c in cs])
    C = C * 10.0 ** rng.uniform(-3, 6, size=(N, 1, 1))
    for k in range(1, N):                       # some views repeated exactly (times 2^m): a homography pair
        if rng.random() < 0.15:
            C[k] = C[rng.integers(k)] * 2.0 ** rng.integers(-3, 4)
    return C


def _same(p: Polynomial, q: Polynomial) -> bool:
    return p.gens == q.gens and list(p.terms.items()) == list(q.terms.items())


@pytest.mark.parametrize("offset", [0.0, 1e6, 1e8])
@pytest.mark.parametrize("with_relations", [False, True])
def test_constraints_equal_the_pair_loop(offset, with_relations):
    rng = np.random.default_rng(int(offset) % 101 + with_relations)
    for N in (2, 3, 5, 9, 16):
        C = _cameras(rng, N, offset)
        gens = tuple(f"v{k}" for k in range(2 * N + 3))
        x_index = rng.permutation(2 * N + 3)[:2 * N]
        rel = centre_relations(C) if with_relations else None
        for pairs in (None, [(i, j) for i in range(N) for j in range(i + 1, N) if rng.random() < 0.5]):
            got, ginfo = corollary1_constraints(C, gens, x_index, pairs, rel)
            ref, rinfo = _reference(C, gens, x_index, pairs, rel)
            errors = ginfo.pop("errors")
            assert ginfo == rinfo
            assert np.isin(errors.rows, np.arange(len(got))).all() and (errors.E >= 0).all()
            assert len(got) == len(ref) and all(_same(p, q) for p, q in zip(got, ref))


def test_shared_generators_take_the_arithmetic():
    """Two views' variables on one generator (x_index not injective): the arithmetic rule, the same polynomials."""
    rng = np.random.default_rng(5)
    C = _cameras(rng, 4, 0.0)
    gens = ("a", "b", "c", "d", "e")
    x_index = np.array([0, 1, 2, 0, 3, 4, 1, 2])
    got, _ = corollary1_constraints(C, gens, x_index)
    ref, _ = _reference(C, gens, x_index)
    assert len(got) == len(ref) > 0 and all(_same(p, q) for p, q in zip(got, ref))


def test_stacked_fundamental_matrices_are_the_per_pair_ones():
    """Bits of F / ||F|| and of the coincidence decision, against fundamental_matrix pair by pair."""
    rng = np.random.default_rng(8)
    for t in range(40):
        N = int(rng.integers(2, 20))
        C = _cameras(rng, N, [0.0, 1e6][t % 2]) if t % 4 else rng.normal(size=(N, 3, 4)) * 10.0 ** rng.uniform(-3, 6)
        I, J = view_pairs(N)
        F, defined, recheck = pair_fundamentals(C, I, J)
        for k, (i, j) in enumerate(zip(I, J)):
            try:
                ref = fundamental_matrix(C[i], C[j])
            except ValueError:
                assert not defined[k] or recheck[k]
                continue
            assert (defined[k] and np.array_equal(F[k], ref)) or recheck[k]
    e = rng.normal(size=(7, 3))
    assert all(np.array_equal(skew_stack(e)[k], _skew(e[k])) for k in range(7))
    A = rng.normal(size=(9, 12)) * 10.0 ** rng.uniform(-5, 5, size=(9, 1))
    assert all(dot_norms(A)[k] == np.linalg.norm(A[k].reshape(3, 4)) for k in range(9))


def test_sum_in_order_is_the_repeated_addition():
    """f = 0 + p_1 + p_2 + ... in one dict: the terms, values and order of Polynomial.__add__, also when sums
    cancel to exactly 0 and the monomial comes back later, and with a polynomial over other generators."""
    from sospoly import sum_in_order

    rng = np.random.default_rng(12)
    gens = ("a", "b", "c")
    for _ in range(200):
        polys = []
        for _ in range(int(rng.integers(0, 7))):
            terms = {tuple(int(k) for k in rng.integers(0, 2, size=3)): float(rng.choice([1.0, -1.0, 0.5, 3.0]))
                     for _ in range(int(rng.integers(1, 4)))}
            polys.append(Polynomial(gens, terms))
        if polys and rng.random() < 0.1:
            polys.insert(int(rng.integers(len(polys))), Polynomial(("a", "b"), {(1, 1): 2.0}))
        ref = Polynomial(gens, {})
        for p in polys:
            ref = ref + p
        got = sum_in_order(gens, polys)
        assert _same(got, ref)


@pytest.mark.parametrize("kind", ["points", "discs"])
def test_built_problem_equals_the_arithmetic(kind):
    """build_problem's objective is the regions' objectives added one by one (the sum it replaced)."""
    from tritools.model.constraints import Method
    from tritools.model.problem import build_problem
    from tritools.model.regions import Ellipse, Point
    from tritools.scene import random_scene

    sc = random_scene(7, 1, seed=4)
    C, x = np.asarray(sc.cameras, float), np.asarray(sc.points2d, float)[0]
    regs = [Point(p) if kind == "points" else Ellipse(p, np.eye(2)) for p in x]
    prob = build_problem(C, regs, Method.COROLLARY1, "dense")
    v = variables(list(prob.gens))
    ref, pos = Polynomial(prob.gens, {}), 2 * len(regs)
    for i, r in enumerate(regs):
        ref = ref + r.polynomials((v[2 * i], v[2 * i + 1]), tuple(v[pos:pos + r.n_aux])).f
        pos += r.n_aux
    assert _same(prob.f, ref) and len(ref.terms) > 3 * len(regs)


def test_delta_min_honours_the_deadline():
    from sospoly import delta_min
    from sospoly.budget import Deadline, TimeLimitReached, deadline_scope

    x = Polynomial(("x",), {(3,): 1.0})
    assert delta_min(x, [x * x] * 100) == 6 and delta_min(Polynomial(("x",), {})) == 0
    with deadline_scope(Deadline.after(0.0)), pytest.raises(TimeLimitReached):
        delta_min(x, [x] * 100)
