"""Projection constraints in the image domain (SPEC §3 and §7).

Theorem 1 (minors)
    M0(v) = [[I2, -x_1] P_1; ...; [I2, -x_N] P_N] is 2N x 4 and affine in v; the image
    points come from one scene point iff every 4x4 minor vanishes.  Row r of M0 is
    ``a_r + t_r c_r`` with ``a_r = P_i[k]``, ``c_r = -P_i[2]`` and ``t_r = x_ik`` a single
    variable, so a minor is multilinear in its rows' variables::

        det M0[R] = sum_{S subset R} prod_{r in S} t_r * det(rows c_r (r in S), a_r (r not in S))

    which gives the coefficient matrix M1 of m1 = M1 b1(v) with numeric 4x4
    determinants only (two rows of one view share c_r, so their product term is 0:
    minors have degree 2, 3 or 4).  SVD M1 = U1 S1 V1^T, N2 = numerical rank
    (``RANK_RTOL``), m2 = S2 V1^T b1: same zero set, N2 <= N1 entries (formed as W M1 from exact or
    extended-precision determinants, with bounds of its coefficients' errors: :mod:`tritools.model.coef_error`).
Corollary 1 (epipolar)
    m1_ij = x~_i^T F_ij x~_j for i < j, F_ij from the camera pair (quadratic).

Both return plain :class:`sospoly.Polynomial` lists; the solver never appears here.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np

from sospoly import Polynomial
from sospoly.budget import check_deadline

from .coef_error import EpipolarErrors, ExactMatrix, MinorErrors, det4, fundamental_errors, minor_rows
from .exact import same_exact_centre
from .centres import dot_norms, group_pairs, merged_labels, pair_fundamentals, stackable, stacked_pair_tests
from .geometry import fundamental_matrix

__all__ = ["Method", "RANK_RTOL", "COEF_RTOL", "minors_matrix", "theorem1_constraints", "corollary1_constraints",
           "triple_minor_constraints", "THEOREM1_DENSE_MAX_VIEWS", "centre_groups", "centre_groups_loop",
           "epipolar_polynomial", "CentreRelations", "centre_relations", "minors_with_error", "minor_count",
           "EXACT_MINORS"]

#: relative singular-value threshold for the numerical rank N2 of M1 (rows scaled to unit norm first).
#: Directions below it are dropped: at an exactly feasible point their values are float
#: round-off amplified by 1/sigma_k, and large multipliers r_k on them move c by
#: r_k * round-off (seen on the corridor point of Example 1: sigma_10/sigma_1 = 8e-10
#: makes the SDP inaccurate, sigma_7..9 ~ 3e-7 give a bound 7e-6 above f at the optimum).
#: Dropping rows only enlarges {m2 = 0}, so the lower bound stays valid (maybe weaker).
RANK_RTOL = 1e-6
#: a term of a minor whose determinant is at most this times the product of its four rows' norms (Hadamard's bound
#: of the determinant) is round-off (:func:`minors_matrix`): a 4 x 4 LU determinant errs by ~4 eps of that bound.
MINOR_ROUNDOFF = 64 * float(np.finfo(float).eps)
#: m2 coefficients below COEF_RTOL * max|row| are SVD round-off and set to zero (this also fixes deg m2_i).
COEF_RTOL = 1e-12
#: Theorem 1's minors are computed exactly (integers; m2 = W M1 then correctly rounded, :mod:`.coef_error`) for at most
#: this many 4x4 minors (C(6, 4) = 15: three views, every triple of the 'views' formulation; ~5 ms), in extended
#: precision with a rounding bound beyond (C(8, 4) = 70 at four views)
EXACT_MINORS = 15


def minor_count(n: int) -> int:
    """C(n, 4): the 4x4 minors of a matrix of n rows (M0 has n = 2N)."""
    return n * (n - 1) * (n - 2) * (n - 3) // 24


class Method(str, enum.Enum):
    """Projection constraints: Theorem 1 (4x4 minors of M0, SVD-reduced) or Corollary 1 (epipolar constraints)."""
    THEOREM1 = "theorem1"
    COROLLARY1 = "corollary1"


def _row_data(cameras: np.ndarray):
    """a_r, c_r and the variable index (0..2N-1, x_i1 -> 2i, x_i2 -> 2i+1) of each M0 row."""
    N = cameras.shape[0]
    a = np.empty((2 * N, 4))
    c = np.empty((2 * N, 4))
    for i, P in enumerate(cameras):
        a[2 * i], a[2 * i + 1] = P[0], P[1]
        c[2 * i] = c[2 * i + 1] = -P[2]
    return a, c, np.arange(2 * N)


@lru_cache(maxsize=32)
def _minor_structure(N: int):
    """Per number of views, the cameras-independent part of M1 (cached).

    Term t of minor R with row subset S is det of the 4 rows ``stack[T[t]]`` of
    ``stack = [a_1..a_2N; c_1..c_2N]`` (c rows for S, a rows otherwise); it adds to
    ``M1[minor[t], mono[t]]``.  Terms with two rows of one view in S are left out
    (equal c rows: determinant 0).  Monomials are numbered in order of first appearance."""
    nrow = 2 * N
    subsets = [S for k in range(5) for S in combinations(range(4), k)]
    monos: dict[tuple, int] = {}
    T, minor, mono = [], [], []
    for ri, R in enumerate(combinations(range(nrow), 4)):
        for S in subsets:
            m = tuple(sorted(R[k] for k in S))
            if len({r // 2 for r in m}) != len(m):
                continue
            T.append([nrow + R[k] if k in S else R[k] for k in range(4)])
            minor.append(ri)
            mono.append(monos.setdefault(m, len(monos)))
    B1 = np.zeros((len(monos), nrow), dtype=np.int64)
    for m, j in monos.items():
        B1[j, list(m)] = 1
    n_minors = ri + 1 if nrow >= 4 else 0
    arr = [np.array(T, np.int64).reshape(-1, 4), np.array(minor, np.int64), np.array(mono, np.int64), B1]
    for x in arr:
        x.setflags(write=False)
    return arr[0], arr[1], arr[2], B1, n_minors


def minors_matrix(cameras: np.ndarray, groups=None, loose=()) -> tuple[np.ndarray, np.ndarray]:
    """M1 and the exponent rows b1 over the 2N image variables (x_11, x_12, ..., x_N2).

    Returns ``(M1, B1)`` with ``m1 = M1 @ b1(x)``; B1 rows are 0/1 exponent vectors.  All
    numeric 4x4 determinants of the module docstring's expansion are taken in one batched
    ``det`` over the cached index structure of :func:`_minor_structure`; monomials whose
    terms all vanish (special cameras) are dropped.

    Views that share a camera centre (:func:`centre_groups`: a duplicated view, a scaled copy, a camera
    rotated about another's centre): the rows of M0 of such views all annihilate that centre, so a term
    whose four rows come from them vanishes identically and is set to exactly 0.  Computed, it is
    round-off (~1e-17), and the unit scaling of M1's rows in :func:`theorem1_constraints` made it a
    constraint the true image points violate (a duplicated view gave c_LB = 6.4 above c = 4 at a
    feasible point).  A threshold on the determinants' size would not do: near-consistent data make
    genuine terms just as small.

    ``loose``: views of a centre group whose centres agree only to round-off and are not admitted
    (:attr:`CentreRelations.loose`).  Every minor with a row of such a view is dropped (all its terms set to 0): its
    float coefficients cannot see the micro-baseline, so minors with rows of two views of the group imply their
    homography to round-off -- the constraint withheld from them (review 9 F2).  A term's rows are the minor's
    rows, so zeroing by term drops whole minors: a relaxation, the bound stays valid.
    """
    M1, B1, _, _ = minors_with_error(cameras, groups, loose)
    return M1.astype(float), B1


def minors_with_error(cameras: np.ndarray, groups=None, loose=(), exact: bool = False) -> tuple:
    """(M1, B1, dM1, M1_exact) of :func:`minors_matrix` with M1 in extended precision (``numpy.longdouble``) and dM1
    >= |M1 - M1 in exact arithmetic| entrywise (:func:`tritools.model.coef_error.det4`; terms set to zero by a rule
    below are exact zeros of a relaxation and carry no error).  ``exact``: M1_exact holds the exact determinants
    (:class:`~tritools.model.coef_error.ExactMatrix`; None otherwise)."""
    cameras = np.asarray(cameras, float)
    a, c, _ = _row_data(cameras)
    T, minor, mono, B1, n_minors = _minor_structure(cameras.shape[0])
    rows = np.vstack([a, c])[T]
    d, err = det4(rows, extended=True)
    # a minor none of whose terms exceeds the rounding of its own determinant (the Hadamard bound of its four
    # rows times MINOR_ROUNDOFF) is the zero polynomial to the data's precision: dropped whole (a relaxation: the
    # bound stays valid).  Kept, the unit scaling of theorem1_constraints turned its round-off into a constraint
    # the true image points violate (review 30a F1: a rectified rig, c_LB = 6.54 above c = 3 at a feasible point).
    noise = np.abs(d) <= MINOR_ROUNDOFF * np.prod(np.linalg.norm(rows, axis=2), axis=1)
    ruled = (np.bincount(minor, weights=~noise, minlength=n_minors) == 0)[minor]
    labels = centre_groups(cameras) if groups is None else np.asarray(groups)
    views = (T % (2 * cameras.shape[0])) // 2                                       # the view of each term's rows
    group = labels[views]                                                           # the centre of each term's rows
    ruled |= np.all(group == group[:, :1], axis=1)
    if len(loose):
        ruled |= np.isin(views, list(loose)).any(axis=1)
    d = np.where(ruled, 0.0, d)
    err = np.where(ruled, 0.0, err)
    M1 = np.zeros((n_minors, B1.shape[0]), d.dtype)
    dM1 = np.zeros((n_minors, B1.shape[0]))
    np.add.at(M1, (minor, mono), d)
    np.add.at(dM1, (minor, mono), err)
    used = np.bincount(mono[(d != 0.0) | (err > 0.0)], minlength=B1.shape[0]) > 0
    M1x = None
    if exact:
        M1x = ExactMatrix.of_terms(rows, ~ruled, minor, mono, (n_minors, B1.shape[0])).columns(np.flatnonzero(used))
    return M1[:, used], B1[used], dM1[:, used], M1x


@dataclass(frozen=True)
class CentreRelations:
    """Which views share a camera centre, decided once on the caller's (raw) cameras: ``groups`` one label per
    view (:func:`centre_groups`), ``coincident`` the pairs (i < j) of one group whose centres coincide in exact
    arithmetic or are admitted (:func:`centre_relations`); the other pairs of a group keep no constraint."""
    groups: np.ndarray
    coincident: frozenset

    @property
    def untied(self) -> tuple:
        """The pairs (i < j) of one group that are not coincident: their centres agree to round-off only."""
        return tuple(p for p in group_pairs(self.groups) if p not in self.coincident)

    @property
    def loose(self) -> frozenset:
        """Views that keep no projection constraint at all: in a group with untied pairs, every view outside the
        class (views tied by ``coincident``) of the group's first view.  Two views of such a group constrained with
        a common third view would fix their relation to round-off -- the homography the exact data do not have
        next to the centre (review 9 F2: epipolar constraints with one outside view whose two epipoles are 1e-14 px
        apart) -- so one class of the group stays and the others are left free: a valid, weaker bound."""
        out = set()
        for g in {int(self.groups[i]) for i, _ in self.untied}:
            views = [int(v) for v in np.flatnonzero(self.groups == g)]
            first = views[0]                            # its class: coincident is exact here, so transitive
            out |= {v for v in views[1:] if (first, v) not in self.coincident}
        return frozenset(out)


def centre_relations(cameras: np.ndarray, groups=None, *, raw=None, admitted=frozenset()) -> CentreRelations:
    """:class:`CentreRelations` of ``cameras`` (N, 3, 4); ``groups`` the centre labels when already decided
    (default :func:`centre_groups`).  A pair of one group is coincident when the caller's float cameras ``raw``
    (default ``cameras``) share its centre exactly, or when it is in ``admitted`` (a round-off pair whose
    micro-baseline ball is excluded, :func:`tritools.model.micro_baseline.admitted_pairs`)."""
    cameras = np.asarray(cameras, float)
    raw = cameras if raw is None else np.asarray(raw, float)
    groups = centre_groups(cameras) if groups is None else np.asarray(groups)
    pairs = frozenset((i, j) for i, j in group_pairs(groups)
                      if _pair_homography(cameras[i], cameras[j], check=False) is not None
                      and ((i, j) in admitted or same_exact_centre(raw[i], raw[j])))
    return CentreRelations(groups, pairs)


def centre_groups(cameras: np.ndarray) -> np.ndarray:
    """One label per view; views whose camera centres coincide share one (the rule of
    :func:`tritools.model.geometry.fundamental_matrix`: F_ij vanishes; Corollary 1 drops such pairs).

    The labels of :func:`centre_groups_loop` (pairs i < j in order, ``label[label == label[j]] = label[i]`` for
    each pair that shares a centre), with the pairs' test stacked
    (:func:`~tritools.model.centres.stacked_pair_tests`): the per-pair rule runs only for pairs the stacked norms
    leave within round-off of the threshold, and for cameras that are not a float (N, 3, 4) stack of valid cameras
    (the loop raises as before)."""
    N = len(cameras)
    if N < 2:
        return np.arange(N)
    check_deadline("comparing the camera centres")
    C = np.asarray(cameras)
    if not stackable(C):
        return centre_groups_loop(cameras)
    same, unsure = stacked_pair_tests(C)
    for i, j in unsure:                                 # near the threshold: the exact per-pair rule
        check_deadline("comparing the camera centres")
        if _same_centre_pair(C[i], C[j]):
            same.append((i, j))
    return merged_labels(N, sorted(same))


def centre_groups_loop(cameras: np.ndarray) -> np.ndarray:
    """:func:`centre_groups` pair by pair (the reference, and the rule for inputs the stacked test refuses)."""
    N = cameras.shape[0]
    label = np.arange(N)
    for i, j in combinations(range(N), 2):
        check_deadline("comparing the camera centres")
        if _same_centre_pair(cameras[i], cameras[j]):
            label[label == label[j]] = label[i]
    return label


def _same_centre_pair(Pi: np.ndarray, Pj: np.ndarray) -> bool:
    """Does :func:`fundamental_matrix` refuse the pair for sharing one centre?  (Other ValueErrors propagate.)"""
    try:
        fundamental_matrix(Pi, Pj)
    except ValueError as exc:
        if "same camera centre" not in str(exc):
            raise
        return True
    return False


@lru_cache(maxsize=64)
def _exponent_tuples(B1_bytes: bytes, shape: tuple, n: int, x_index: tuple) -> tuple:
    B1 = np.frombuffer(B1_bytes, dtype=np.int64).reshape(shape)
    E = np.zeros((shape[0], n), dtype=np.int64)
    E[:, list(x_index)] = B1
    return tuple(tuple(int(k) for k in row) for row in E)


def theorem1_constraints(cameras: np.ndarray, gens, x_index, groups=None, loose=()
                         ) -> tuple[list[Polynomial], dict]:
    """m2 of Theorem 1 as polynomials in ``gens``.

    ``x_index[2i + k]`` is the position in ``gens`` of x_{i+1, k+1}.  ``groups``: the views' centre labels
    (:class:`CentreRelations`, decided on the caller's raw cameras; default: from ``cameras``).  Returns
    the list and diagnostics (N1, N2, singular values, and ``errors``: the rows' coefficient error bounds,
    :class:`~tritools.model.coef_error.MinorErrors`).
    """
    exact = minor_count(2 * cameras.shape[0]) <= EXACT_MINORS
    M1x, B1, dM1, M1e = minors_with_error(cameras, groups, loose, exact=exact)
    M1 = M1x.astype(float)
    norms = np.linalg.norm(M1, axis=1)
    keep = norms > 0
    M1n = M1[keep] / norms[keep, None]
    U, S, Vt = np.linalg.svd(M1n, full_matrices=False)
    n2 = int(np.sum(S > RANK_RTOL * S[0])) if S.size else 0
    # m2 = S2 V2^T = U2^T M1n, formed as W M1 from the extended determinants (coef_error's module docstring), each
    # row at unit scale (same zero set, better conditioned SDP); round-off coefficients to 0 (charged in E)
    W = U[:, :n2].T / norms[keep][None, :]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        W = W / np.max(np.abs(S[:n2, None] * Vt[:n2]), axis=1, keepdims=True) if n2 else W
    M2, E = minor_rows(W, M1x[keep], dM1[keep]) if M1e is None else M1e.rows(keep).times(W)
    small = np.abs(M2) <= COEF_RTOL * np.max(np.abs(M2), axis=1, keepdims=True) if n2 else np.zeros_like(M2, bool)
    E = E + np.where(small, np.abs(M2), 0.0)
    M2 = np.where(small, 0.0, M2)
    gens = tuple(gens)
    exps = _exponent_tuples(np.ascontiguousarray(B1).tobytes(), B1.shape, len(gens),
                            tuple(int(k) for k in x_index))
    if not np.all(np.isfinite(M2)):
        raise ValueError("cameras: the 4x4 minors of M0 are not finite (overflowing camera entries?)")
    # the rows are finite and their entries non-zero on distinct int exponent tuples: the
    # polynomials are built without Polynomial's per-term validation (4000+ terms at N = 4)
    polys = []
    for row in M2:
        check_deadline("building the minors")
        nz = np.nonzero(row)[0]
        polys.append(Polynomial.from_trusted_terms(gens, dict(zip([exps[k] for k in nz], row[nz].tolist()))))
    errors = MinorErrors(np.arange(n2), np.array(exps, dtype=np.int64).reshape(-1, len(gens)), E)
    return polys, {"N1": M1.shape[0], "N2": n2, "singular_values": S, "errors": errors}


#: Theorem 1 with all C(2N, 4) minors is built for at most this many views; beyond, the minors of view
#: triples (:func:`triple_minor_constraints`) are used (C(20, 4) = 4845 minors at N = 10 already).
THEOREM1_DENSE_MAX_VIEWS = 8


def triple_minor_constraints(cameras: np.ndarray, gens, x_index, triples, groups=None, loose=()
                             ) -> tuple[list[Polynomial], dict]:
    """Theorem 1's constraints restricted to view triples: for each triple (i, j, k) the 4x4 minors of the
    six rows of M0 of those views, reduced by SVD as in :func:`theorem1_constraints`.

    Every minor of a triple is a minor of the full M0, so {m = 0} over the triples contains the image of
    the scene points: a relaxation of rank M0 < 4 (the lower bound stays valid).  For a chain of
    overlapping triples it is exact at generic configurations (consecutive triples share two views,
    which fix the point).  ``info["views"]`` gives the triple of each returned polynomial."""
    x_index = np.asarray(x_index)
    polys, views, errors, n1, n2 = [], [], [], 0, 0
    for t in triples:
        check_deadline("building the minors")
        t = tuple(int(i) for i in t)
        sub = np.concatenate([x_index[2 * i:2 * i + 2] for i in t])
        local = [t.index(i) for i in loose if i in t]
        p, info = theorem1_constraints(cameras[list(t)], gens, sub,
                                       None if groups is None else np.asarray(groups)[list(t)], local)
        errors.append(info["errors"].shifted(len(polys)))
        polys += p
        views += [t] * len(p)
        n1 += info["N1"]
        n2 += info["N2"]
    return polys, {"N1": n1, "N2": n2, "views": views, "errors": tuple(errors)}


def corollary1_constraints(cameras: np.ndarray, gens, x_index, pairs=None, relations=None
                           ) -> tuple[list[Polynomial], dict]:
    """The epipolar constraints x~_i^T F_ij x~_j (SPEC §7) of the view pairs ``pairs`` (default all i < j),
    F_ij scaled to unit norm.

    A pair whose camera centres coincide (a duplicated view, a rotation about the centre) has no fundamental
    matrix: its views are related by the homography H = M_j M_i^-1 (M the left 3x3 blocks, P_j = H P_i), and
    it carries the three bilinear constraints x~_j x (H x~_i) = 0 instead (rank 2; ``info["homography"]``).
    Without them the pair would carry nothing and the relaxation would never be tight when the two views'
    regions differ.  A pair with no constraint at all (centres at infinity) is ``info["skipped"]``.
    ``info["pairs"]`` gives the pair of each returned polynomial, in order.

    ``relations`` (:func:`centre_relations` of the caller's *raw* cameras, when ``cameras`` are normalised
    ones): which pairs share a centre is decided there, where it is exact -- a normalisation can magnify a
    baseline of round-off size (1e-11 of |C|) into a "fundamental matrix" whose constraints cut off the
    optimum.  Pairs with one centre by the raw test but no exact homography are skipped."""
    gens = tuple(gens)
    n = len(gens)
    N = cameras.shape[0]
    pairs = [(i, j) for i in range(N) for j in range(i + 1, N)] if pairs is None else [tuple(p) for p in pairs]

    def var(k):
        e = [0] * n
        e[x_index[k]] = 1
        return Polynomial(gens, {tuple(e): 1.0})

    one = Polynomial.constant(1.0, gens)
    views: dict[int, list] = {}

    def xt(i):                                          # (x_i1, x_i2, 1), made when a pair needs the arithmetic
        if i not in views:
            views[i] = [var(2 * i), var(2 * i + 1), one]
        return views[i]

    Fs = _epipolar_matrices(cameras, pairs)
    Es = _epipolar_errors(cameras, pairs, Fs)
    mono = _Monomials(n, x_index)
    polys, kept, skipped, homography, errors = [], [], [], [], []
    loose = relations.loose if relations is not None else frozenset()
    for (i, j), F in zip(pairs, Fs):
        check_deadline("building the epipolar constraints")
        if i in loose or j in loose:                    # CentreRelations.loose: no constraint at all
            skipped.append((i, j))
            continue
        if F is None or (relations is not None and relations.groups[i] == relations.groups[j]):
            if relations is None:                       # one centre (or no fundamental matrix): the homography
                H = _pair_homography(cameras[i], cameras[j])
            else:
                H = _pair_homography(cameras[i], cameras[j], check=False) if (i, j) in relations.coincident \
                    else None
            if H is None:
                skipped.append((i, j))
                continue
            Hx = [sum((float(H[a, b]) * xt(i)[b] for b in range(3) if H[a, b] != 0.0), Polynomial(gens, {}))
                  for a in range(3)]
            for a in range(3):                              # (x~_j x H x~_i)_a
                b, c = (a + 1) % 3, (a + 2) % 3
                polys.append(xt(j)[b] * Hx[c] - xt(j)[c] * Hx[b])      # (H's error is not bounded here)
                kept.append((i, j))
            homography.append((i, j))
            continue
        terms = mono.bilinear(i, j, F)
        polys.append(Polynomial.from_trusted_terms(gens, terms) if terms is not None
                     else epipolar_polynomial(gens, F, xt(i), xt(j)))
        if (i, j) in Es:
            errors.append((len(polys) - 1, [x_index[2 * i], x_index[2 * i + 1], x_index[2 * j], x_index[2 * j + 1]],
                           Es[(i, j)]))
        kept.append((i, j))
    rows, gvars, E = zip(*errors) if errors else ((), np.zeros((0, 4)), np.zeros((0, 3, 3)))
    errs = EpipolarErrors(np.array(rows, dtype=np.intp), np.array(gvars, dtype=np.intp).reshape(-1, 4),
                          np.array(E, float).reshape(-1, 3, 3))
    return polys, {"N1": len(polys), "N2": len(polys), "pairs": kept, "skipped": skipped, "homography": homography,
                   "errors": errs}


def epipolar_polynomial(gens: tuple, F: np.ndarray, xi: list, xj: list) -> Polynomial:
    """x~_i^T F x~_j by polynomial arithmetic, ``xi``/``xj`` the polynomials (x_1, x_2, 1) of the two views (the
    reference of :meth:`_Monomials.bilinear`, and the rule where the two views' variables are not distinct)."""
    p = Polynomial(gens, {})
    for a in range(3):
        for b in range(3):
            if F[a, b] != 0.0:
                p = p + float(F[a, b]) * xi[a] * xj[b]
    return p


class _Monomials:
    """The exponent tuples of x~_i^T F x~_j over ``n`` generators (``x_index``: the generator of each image
    variable), the linear and constant ones shared between pairs."""

    def __init__(self, n: int, x_index):
        self.n, self.x = n, [int(k) for k in x_index]
        self.lin: dict[int, tuple] = {}
        self.const = (0,) * n

    def _linear(self, v: int) -> tuple:
        if v not in self.lin:
            e = [0] * self.n
            e[v] = 1
            self.lin[v] = tuple(e)
        return self.lin[v]

    def bilinear(self, i: int, j: int, F: np.ndarray) -> dict | None:
        """{exponent: F[a, b]} in the order (a, b) of :func:`epipolar_polynomial`, its terms (the four variables
        are distinct, so each (a, b) has its own monomial and the sum is the coefficients themselves); None when
        the variables of views i and j are not four distinct generators or F is not finite (the arithmetic refuses
        it)."""
        u = (self.x[2 * i], self.x[2 * i + 1], self.x[2 * j], self.x[2 * j + 1])
        if len(set(u)) != 4 or not np.isfinite(F).all():
            return None
        terms = {}
        for a, b in zip(*np.nonzero(F)):
            if a < 2 and b < 2:
                e = [0] * self.n
                e[u[a]] = e[u[2 + b]] = 1
                terms[tuple(e)] = float(F[a, b])
            else:
                terms[self.const if a == b == 2 else self._linear(u[a] if a < 2 else u[2 + b])] = float(F[a, b])
        return terms


def _epipolar_matrices(cameras: np.ndarray, pairs: list) -> list:
    """Per pair, ``F / ||F||`` for F = ``fundamental_matrix(cameras[i], cameras[j])`` (normalised once more, as the
    constraints always were), or None where that raises (one centre, bad cameras): stacked
    (:func:`~tritools.model.centres.pair_fundamentals`, the same numbers) for a valid float stack, pair by pair
    otherwise and where the stacked norm is within round-off of the threshold."""
    C = np.asarray(cameras)
    if not pairs:
        return []
    if not stackable(C):
        return [_epipolar_matrix(C[i], C[j]) for i, j in pairs]
    I, J = (np.array(v, dtype=np.intp) for v in zip(*pairs))
    F, defined, recheck = pair_fundamentals(C, I, J)
    F = F / np.where(defined, dot_norms(F.reshape(len(F), 9)), 1.0)[:, None, None]
    out = [F[k] if defined[k] else None for k in range(len(F))]
    for k in np.flatnonzero(recheck):
        check_deadline("computing the fundamental matrices")
        out[k] = _epipolar_matrix(C[I[k]], C[J[k]])
    return out


def _epipolar_errors(cameras: np.ndarray, pairs: list, Fs: list) -> dict:
    """{pair: E (3, 3)} bounds of each computed F's coefficient error (:func:`~.coef_error.fundamental_errors`)
    for the pairs with a matrix."""
    idx = [k for k, F in enumerate(Fs) if F is not None]
    if not idx:
        return {}
    C = np.asarray(cameras, float)
    I = np.array([pairs[k][0] for k in idx], dtype=np.intp)
    J = np.array([pairs[k][1] for k in idx], dtype=np.intp)
    E = fundamental_errors(np.array([Fs[k] for k in idx]), C[I], C[J])
    return {pairs[k]: E[m] for m, k in enumerate(idx)}


def _epipolar_matrix(Pi: np.ndarray, Pj: np.ndarray) -> np.ndarray | None:
    """``F / ||F||`` of ``fundamental_matrix(Pi, Pj)``, None where it raises (:func:`_epipolar_matrices`)."""
    try:
        F = fundamental_matrix(Pi, Pj)
    except ValueError:
        return None
    return F / np.linalg.norm(F)


def _pair_homography(Pi: np.ndarray, Pj: np.ndarray, check: bool = True) -> np.ndarray | None:
    """H with P_j = H P_i up to scale (unit Frobenius norm), for two cameras with the same finite centre; None
    when the left 3x3 block of P_i is singular (centre at infinity) or (``check``) the two float cameras do not
    have one centre in exact arithmetic (:func:`tritools.model.exact.same_exact_centre`).

    The test is exact on purpose: the constraints hold only if the centres coincide.  A pair whose centres agree
    to round-off only (a rig built as K R [I | -C] in floats: ~1e-16 of |C| apart) has a micro-baseline, and
    next to the centres the exact problem has parallax and lower costs than any point the homography admits
    (review 8b: certified 4.353 where a float point 3e-9 from the centres has exact cost 4.007); such a pair
    keeps no constraint at all, which is weaker but sound.  ``check=False``: the caller decided coincidence on
    the raw cameras (``cameras`` are normalised ones, whose rounding broke the exact relation)."""
    Mi, Mj = Pi[:, :3], Pj[:, :3]
    rows = np.linalg.norm(Mi, axis=1, keepdims=True)
    if not np.all(rows > 0) or np.linalg.cond(Mi / rows) > 1e8:
        return None            # (rows equilibrated: pixel units do not decide it, review 38b M2: 2^17 px refused)
    if check and not same_exact_centre(Pi, Pj):
        return None
    H = Mj @ np.linalg.inv(Mi)
    if not np.all(np.isfinite(H)):
        return None
    return H / np.linalg.norm(H)
