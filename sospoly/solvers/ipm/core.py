"""The one Mehrotra predictor-corrector skeleton of the interior-point method.

Problem (the conic standard form of :mod:`sospoly.lowering.conic`, Clarabel's), a dual-form LMI::

    min q^T x   s.t.  A_E x = b_E,   S_k = smat(b_k - A_k x) >= 0   (k = 1..K blocks)

with free scalars x, whose dual is  min <C, Z> + b_E^T z_E  s.t.  <A_i, Z> + (A_E^T z_E)_i = -q_i,
Z >= 0.  Method: infeasible-start Mehrotra predictor-corrector with the HKM direction

    dZ = sym(K S^-1) - Z - sym(Z dS S^-1),   K = sigma mu I - dZ_aff dS_aff,

which reduces every Newton step to the Schur complement system of the size of the free scalars,
M_ij = sum_k tr(A_{k,i} Z_k A_{k,j} S_k^-1), augmented by A_E when there are equality rows.

Only the linear maps differ between formulations; they are an :class:`Operator` (apply A_k,
its adjoint, A_E and its adjoint, and *factor*: form and factorise the Newton system for the
current iterate).  :func:`mehrotra` runs the same iteration for all of them, on a batch of B
instances sharing one structure (instances that finish leave the active set):

* :class:`~.operators.DenseOperator` -- dense batched A (B instances at once);
* :class:`~.operators.SparseOperator` -- one instance with sparse A (svec-Kronecker Schur);
* :class:`~.moment.MomentReduction` -- one single-block image-form instance in its reduced
  moment form (disjoint-support adjoint matrices, fast Schur complement).

Stopping rule (Clarabel's, with :class:`~sospoly.tolerances.Tolerances`): see
:func:`stopping_rule`.  An instance that does not meet it within ``ipm_max_iter`` iterations,
stalls, diverges (infeasible or unbounded problems: this method has no infeasibility
certificates) or runs past the deadline is reported ``converged = False`` with the reason;
callers fall back to Clarabel.  Nothing here is trusted either way: the a-posteriori
certificate checks of :mod:`sospoly.solvers.solve` run on the returned x.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ...algebra.svec import smat, svec
from ...budget import cpu_share
from ...tolerances import Tolerances
from ..level import IPM_LEVEL

__all__ = ["IpmResult", "Layout", "layout_of", "Operator", "stopping_rule", "mehrotra", "Iterate", "out_of_time",
           "predicted_iteration", "IPM_SECONDS_PER_UNIT", "FLAT_STALL_RATIO",
           "stalled_rule"]


@dataclass(frozen=True)
class IpmResult:
    """Per-instance outcome of a batch (arrays have a leading batch axis)."""
    converged: np.ndarray        # (B,) bool
    x: np.ndarray                # (B, m)
    z: np.ndarray                # (B, n_rows): z_E then the svec blocks (Clarabel's row order)
    s: np.ndarray                # (B, n_rows)
    primal_objective: np.ndarray
    dual_objective: np.ndarray
    iterations: np.ndarray       # (B,) int
    reason: tuple                # per instance: "" or why it did not converge


class Layout:
    """Row layout: p zero rows, then PSD blocks of sides ``sizes`` (svec rows)."""

    def __init__(self, n_zero: int, sizes):
        self.p = int(n_zero)
        self.sizes = tuple(int(n) for n in sizes)
        self.starts = []
        r = self.p
        for n in self.sizes:
            self.starts.append(r)
            r += n * (n + 1) // 2
        self.n_rows = r
        self.nu = sum(self.sizes)   # degree of the cone (mu = <S, Z> / nu)

    def block(self, k) -> slice:
        n = self.sizes[k]
        return slice(self.starts[k], self.starts[k] + n * (n + 1) // 2)


def layout_of(cones) -> Layout:
    """Layout from sospoly cones: at most one leading zero cone, then PSD cones only."""
    p, sizes = 0, []
    for i, c in enumerate(cones):
        if c.kind == "zero" and i == 0:
            p = c.dim
        elif c.kind == "psd":
            sizes.append(c.size)
        else:
            raise ValueError(f"the interior-point solver handles a leading zero cone and PSD cones only, "
                             f"got a {c.kind!r} cone at position {i}")
    return Layout(p, sizes)


class Operator:
    """The linear maps of one formulation for the active instances (see the module docstring)."""

    def apply(self, k: int, x: np.ndarray) -> np.ndarray:        # A_k x, (B, L_k)
        raise NotImplementedError

    def adjoint(self, k: int, v: np.ndarray) -> np.ndarray:      # A_k^T v, (B, m)
        raise NotImplementedError

    def eq_apply(self, x: np.ndarray) -> np.ndarray:             # A_E x, (B, p)
        raise NotImplementedError

    def eq_adjoint(self, z: np.ndarray) -> np.ndarray:           # A_E^T z, (B, m)
        raise NotImplementedError

    def factor(self, Z: list, R: list):
        """A solver ``solve(r_x, r_E) -> (dx, dz_E)`` of [[M, A_E^T], [A_E, 0]] for the iterate with duals
        Z and inverse slacks R = S^-1 (per block); raises LinAlgError when M cannot be factorised."""
        raise NotImplementedError

    def subset(self, idx: np.ndarray) -> Operator:
        """The operator of the instances ``idx`` of the batch."""
        raise NotImplementedError

    def restore(self, dZ: list, rD: np.ndarray, dzE: np.ndarray) -> list:
        """Optional exact restoration of the dual linear equations after a step (default: none)."""
        return dZ


def stopping_rule(tol: Tolerances, pobj, dobj, *, rdx, pres, dres, pscale, dscale, xzinf):
    """(converged, diverged), on scalars or on (B,) arrays.

    |pobj - dobj| <= solver_gap_abs or <= solver_gap_rel min(|pobj|, |dobj|);
    ||A x + s - b||_inf <= solver_feas max(1, ||b|| + ||x|| + ||s||) (``pres``, ``pscale``);
    ||A^T z + q||_inf <= solver_feas max(1, ||q|| + ||z||) (``dres``, ``dscale``).
    pobj - dobj = <S, Z> + z^T r_P + r_D^T x exactly (``rdx`` = r_D^T x).  With large multipliers x
    (nearly dependent constraints) the last term stalls above the gap tolerance although the iterate
    is optimal to working precision; accepted also when the complementarity part meets the gap
    tolerance and |r_D^T x| stays below ipm_dual_residual_gap relative (Tolerances documents it).
    ``xzinf`` = max(||x||, ||z||) beyond ``ipm_divergence``: diverged."""
    gap = np.abs(pobj - dobj)
    feas_ok = (pres <= tol.solver_feas * np.maximum(1.0, pscale)) & (dres <= tol.solver_feas * np.maximum(1.0, dscale))
    ok = ((gap <= tol.solver_gap_abs) | (gap <= tol.solver_gap_rel * np.minimum(np.abs(pobj), np.abs(dobj)))) \
        & feas_ok
    comp = np.abs(pobj - dobj - rdx)
    scale_obj = np.maximum(1.0, np.abs(pobj))
    ok = ok | (feas_ok & ((comp <= tol.solver_gap_abs) | (comp <= tol.solver_gap_rel * scale_obj))
               & (np.abs(rdx) <= tol.ipm_dual_residual_gap * scale_obj))
    diverged = ~np.isfinite(pobj) | ~np.isfinite(dobj) | (xzinf > tol.ipm_divergence)
    return ok, diverged


_trtri = sla.lapack.dtrtri
_syevr = sla.lapack.dsyevr


def _inverse_cholesky(X: np.ndarray) -> np.ndarray:
    """L^-1 for X = L L^T (stack (B, n, n)); LinAlgError when X is not positive definite."""
    L = np.linalg.cholesky(X)
    if X.shape[0] == 1:
        Li, info = _trtri(L[0], lower=1)
        if info:
            raise np.linalg.LinAlgError("singular Cholesky factor")
        return Li[None]
    return np.linalg.inv(L)


def _max_step(Li: np.ndarray, dX: np.ndarray) -> np.ndarray:
    """Largest a with X + a dX >= 0 (inf when dX >= 0) for X = L L^T > 0 given Li = L^-1; batched."""
    T = Li @ dX @ np.swapaxes(Li, -1, -2)
    T = 0.5 * (T + np.swapaxes(T, -1, -2))
    if T.shape[0] == 1:
        w, _, _, _, info = _syevr(T[0], compute_v=0, range="I", il=1, iu=1)      # smallest eigenvalue only
        if info:
            raise np.linalg.LinAlgError("eigenvalue computation failed")
        lam1 = float(w[0])          # the rule below on a Python float (no errstate / where on a 1-vector)
        return np.array([-1.0 / min(lam1, -1e-300) if lam1 < 0 else np.inf])
    lam = np.linalg.eigvalsh(T)[..., 0]
    with np.errstate(divide="ignore"):
        return np.where(lam < 0, -1.0 / np.minimum(lam, -1e-300), np.inf)


@dataclass
class Iterate:
    """x (B, m), z_E (B, p), slacks S_k and duals Z_k (lists of (B, n_k, n_k)) of a batch."""
    x: np.ndarray
    zE: np.ndarray
    S: list
    Z: list


def _start(q: np.ndarray, b: np.ndarray, lay: Layout) -> Iterate:
    """The infeasible start: x = 0, z_E = 0, S_k = max(1, ||b||_inf) I, Z_k = max(1, ||q||_inf) I."""
    B, m = q.shape
    scale_s = np.maximum(1.0, np.abs(b).max(axis=1))
    scale_z = np.maximum(1.0, np.abs(q).max(axis=1))
    return Iterate(np.zeros((B, m)), np.zeros((B, lay.p)), [scale_s[:, None, None] * np.eye(n) for n in lay.sizes],
                   [scale_z[:, None, None] * np.eye(n) for n in lay.sizes])


@dataclass(frozen=True)
class _Residuals:
    """Residuals and objectives of the active instances at one iterate:
    rP_k = b_k - A_k x - svec(S_k),  rE = b_E - A_E x,  rD = q + A_E^T z_E + sum_k A_k^T svec(Z_k),
    pobj = q^T x,  dobj = -(b_E^T z_E + sum_k b_k^T svec(Z_k)), with the infinity norms of the stopping rule."""
    rP: list
    rE: np.ndarray
    rD: np.ndarray
    pobj: np.ndarray
    dobj: np.ndarray
    xinf: np.ndarray
    sinf: np.ndarray
    zinf: np.ndarray
    pres: np.ndarray
    dres: np.ndarray


def _residuals(sub: Operator, qa, ba, bka: list, x, zE, S: list, Z: list, lay: Layout) -> _Residuals:
    """:class:`_Residuals` of the active instances (``qa``, ``ba``, ``bka``: their costs, right-hand sides and
    per-block right-hand sides)."""
    p, nb, m = lay.p, len(lay.sizes), x.shape[1]
    svs, svz = [svec(Sk) for Sk in S], [svec(Zk) for Zk in Z]
    rP = [bka[k] - sub.apply(k, x) - svs[k] for k in range(nb)]
    rE = ba[:, :p] - sub.eq_apply(x) if p else np.zeros((x.shape[0], 0))
    rD = qa + (sub.eq_adjoint(zE) if p else 0.0) + sum(sub.adjoint(k, svz[k]) for k in range(nb))
    pobj = np.einsum("bm,bm->b", qa, x)
    dobj = -(np.einsum("bp,bp->b", ba[:, :p], zE) + sum(np.einsum("bl,bl->b", bka[k], svz[k]) for k in range(nb)))
    xinf = np.abs(x).max(axis=1) if m else np.zeros(x.shape[0])
    sinf = np.max([np.abs(v).max(axis=1) for v in svs], axis=0)
    zinf = np.max([np.abs(v).max(axis=1) for v in svz] + ([np.abs(zE).max(axis=1)] if p else []), axis=0)
    pres = np.max([np.abs(r).max(axis=1) for r in rP] + ([np.abs(rE).max(axis=1)] if p else []), axis=0)
    dres = np.abs(rD).max(axis=1) if m else np.zeros(x.shape[0])
    return _Residuals(rP, rE, rD, pobj, dobj, xinf, sinf, zinf, pres, dres)


class _Newton:
    """The HKM Newton system of the active instances at one iterate (module docstring):
    dZ = sym(K R) - Z - sym(Z dS R) with R = S^-1, dS = smat(rP - A dx), dx from the Schur complement."""

    def __init__(self, sub: Operator, S: list, Z: list, r: _Residuals, lay: Layout):
        self.LiS = [_inverse_cholesky(Sk) for Sk in S]
        self.LiZ = [_inverse_cholesky(Zk) for Zk in Z]
        self.R = [np.swapaxes(Li, -1, -2) @ Li for Li in self.LiS]
        self.solve = sub.factor(Z, self.R)
        self.sub, self.S, self.Z, self.r, self.lay = sub, S, Z, r, lay

    def prepare(self) -> None:
        """mu = sum_k <S_k, Z_k> / nu, and the parts of the right-hand side shared by both directions."""
        S, Z, R, lay = self.S, self.Z, self.R, self.lay
        self.mu = sum(np.einsum("bij,bij->b", Sk, Zk) for Sk, Zk in zip(S, Z)) / lay.nu
        self.rPm = [smat(r, n) for r, n in zip(self.r.rP, lay.sizes)]
        self.ZrR = [Z[k] @ self.rPm[k] @ R[k] for k in range(len(lay.sizes))]

    def direction(self, Kmats):
        """(dx, dz_E, dS, dZ) for the matrices K_k (None: K_k = 0, the affine predictor)."""
        sub, Z, R, nb = self.sub, self.Z, self.R, len(self.lay.sizes)
        rhs = -np.array(self.r.rD, dtype=float)
        KR = [Kmats[k] @ R[k] if Kmats[k] is not None else 0.0 for k in range(nb)]
        for k in range(nb):
            rhs -= sub.adjoint(k, svec(KR[k] - Z[k] - self.ZrR[k]))
        dx, dzE = self.solve(rhs, self.r.rE)
        dS, dZ = [], []
        for k in range(nb):
            dSk = self.rPm[k] - smat(sub.apply(k, dx), self.lay.sizes[k])
            dZk = KR[k] - Z[k] - Z[k] @ dSk @ R[k]
            dS.append(dSk)
            dZ.append(0.5 * (dZk + np.swapaxes(dZk, 1, 2)))
        return dx, dzE, dS, sub.restore(dZ, self.r.rD, dzE)

    def steps(self, dS, dZ):
        """The largest primal and dual steps that keep S and Z positive semidefinite."""
        nb = len(self.lay.sizes)
        ap = np.min([_max_step(self.LiS[k], dS[k]) for k in range(nb)], axis=0)
        ad = np.min([_max_step(self.LiZ[k], dZ[k]) for k in range(nb)], axis=0)
        return ap, ad

    def predictor_corrector(self):
        """Mehrotra: the affine direction, sigma = (mu_aff / mu)^3, then the corrected direction with
        K_k = sigma mu I - dZ_aff dS_aff; returns (dx, dz_E, dS, dZ, a_primal, a_dual) (steps unscaled)."""
        S, Z, mu, lay = self.S, self.Z, self.mu, self.lay
        dx, dzE, dS, dZ = self.direction([None] * len(lay.sizes))
        ap, ad = self.steps(dS, dZ)
        ap1, ad1 = np.minimum(1.0, ap), np.minimum(1.0, ad)
        mu_aff = sum(np.einsum("bij,bij->b", S[k] + ap1[:, None, None] * dS[k], Z[k] + ad1[:, None, None] * dZ[k])
                     for k in range(len(lay.sizes))) / lay.nu
        sigma = np.clip((mu_aff / np.maximum(mu, 1e-300)) ** 3, 0.0, 1.0)
        Kc = [sigma[:, None, None] * mu[:, None, None] * np.eye(n) - dZ[k] @ dS[k] for k, n in enumerate(lay.sizes)]
        dx, dzE, dS, dZ = self.direction(Kc)
        ap, ad = self.steps(dS, dZ)
        return dx, dzE, dS, dZ, ap, ad


def _take_step(it_: Iterate, active, x, zE, S, Z, step, frac: float) -> None:
    """Move the active instances by ``frac`` of the largest steps (capped at 1)."""
    dx, dzE, dS, dZ, ap, ad = step
    ap = np.minimum(1.0, frac * ap)
    ad = np.minimum(1.0, frac * ad)
    it_.x[active] = x + ap[:, None] * dx
    if zE.shape[1]:
        it_.zE[active] = zE + ad[:, None] * dzE
    for k in range(len(S)):
        it_.S[k][active] = S[k] + ap[:, None, None] * dS[k]
        it_.Z[k][active] = Z[k] + ad[:, None, None] * dZ[k]


_SINGULAR = "singular Schur complement or lost positive definiteness"


def _why(ok, diverged, stalled, timeout) -> str:
    return "" if ok else "diverged (infeasible or unbounded?)" if diverged else \
        "stalled" if stalled else "time limit" if timeout else "iteration limit"


#: seconds of one iteration per unit of B (m sum_k n_k^3 + m^3 / 3) -- the Schur complement's products over
#: the PSD blocks of sides n_k and its Cholesky factor, m columns, B instances -- on a core of its own.  Measured
#: first iterations (2-4x the later ones: the work arrays are paged in) of dense degree-2 programs, 20-50 views
#: with points, discs and mixed regions: 1.0-3.4e-9 s per unit under a load average of ~5 on 2 cores (0.4-1.4e-9
#: on a core of its own).
IPM_SECONDS_PER_UNIT = 1e-9


def predicted_iteration(B: int, m: int, sizes) -> float:
    """Predicted wall seconds of the first iteration (:data:`IPM_SECONDS_PER_UNIT`, over the share of a core this
    process can expect now, :func:`sospoly.budget.cpu_share`): what :func:`out_of_time` compares with the time
    left before there is a measured iteration."""
    units = float(B) * (float(m) * sum(float(n) ** 3 for n in sizes) + float(m) ** 3 / 3.0)
    return IPM_SECONDS_PER_UNIT * units / cpu_share()


def out_of_time(deadline, last_iteration: float) -> bool:
    """Has ``deadline`` (a :class:`sospoly.budget.Deadline` or None) passed, or is what is left of it shorter
    than the last iteration took?  An iteration cannot be interrupted (its Schur complement and factorisation
    are one native call each: ~0.5-1.5 s at 30-50 views with dense degree-2 programs), so the next one would
    end past the deadline by about the difference: stopping one iteration early keeps the time limit."""
    if deadline is None or deadline.end is None:
        return False
    left = deadline.end - time.monotonic()
    return left <= 0.0 or left < last_iteration


#: ``flat_stall``: also stalled when the merit fell by less than this factor's complement over the last two
#: iterations (from iteration 8, like the halving rule).  Traces of the moment form (every solve of the fast test
#: tier and a workload of Theorem 1 / Corollary 1 delta = 4, mixed-region and robust calls): its stalls sit on a
#: plateau (the merit within a few % from one iteration to the next) for 2-5 iterations before the halving rule
#: fires, and no converging run had such a plateau from iteration 8 (benchmarks/RESULTS.md, wave 12).
FLAT_STALL_RATIO = 0.9


def stalled_rule(it: int, merit: np.ndarray, history: np.ndarray, flat: bool = False) -> np.ndarray:
    """Stalled instances at iteration ``it`` (from 8 on): the merit |pobj - dobj| + pres + dres (B,) has not halved
    against ``history[:, 0]`` (the merits of the last five iterations (B, 5), oldest first); with ``flat`` also
    where it fell by less than 1 - :data:`FLAT_STALL_RATIO` against ``history[:, -2]`` (two iterations back)."""
    stalled = (it >= 8) & (merit > 0.5 * history[:, 0])
    if flat:
        stalled |= (it >= 8) & (merit > FLAT_STALL_RATIO * history[:, -2])
    return stalled


def mehrotra(op: Operator, q: np.ndarray, b: np.ndarray, lay: Layout, tol: Tolerances, deadline=None, stop=None, *,
             flat_stall: bool = False):
    """Run the predictor-corrector on a batch; returns (Iterate, converged, iterations, reasons).

    ``q`` (B, m) the costs, ``b`` (B, n_rows) the right-hand sides (zero rows first, then svec
    blocks), ``op`` the operator of the whole batch (:meth:`Operator.subset` gives the active part).
    An instance stops at the stopping rule (:func:`stopping_rule`), when its merit |pobj - dobj| + pres + dres
    has not halved over the last 4 iterations (stalled), at ``ipm_max_iter``, at the deadline
    (:func:`out_of_time`: also when less time is left than the last iteration took, or than the first is
    predicted to take, :func:`predicted_iteration`), or where ``stop(active, iterate, residuals)`` (bool per
    active instance; optional) says so (reason :data:`IPM_LEVEL`, not converged: the caller judges that
    iterate).  ``flat_stall``: also stalled on a plateau of two iterations (:data:`FLAT_STALL_RATIO`), for
    callers whose fallback does not start from this iterate."""
    B = q.shape[0]
    bk = [b[:, lay.block(k)] for k in range(len(lay.sizes))]
    it_ = _start(q, b, lay)
    nb_inf, nq_inf = np.abs(b).max(axis=1), np.abs(q).max(axis=1)
    converged, its, reason = np.zeros(B, bool), np.zeros(B, int), [""] * B
    active = np.arange(B)
    history = np.full((B, 5), np.inf)    # last merit values (gap + residuals) per instance

    def finish(idx, it, why):
        for g in idx:
            its[g], reason[g] = it, why

    # how long the next iteration may take (predicted for the first, then the last one measured), when it started
    last = 0.0 if deadline is None or deadline.end is None else predicted_iteration(B, q.shape[1], lay.sizes)
    t_it = None
    for it in range(tol.ipm_max_iter + 1):
        now = time.monotonic()
        if t_it is not None:
            last = now - t_it
        t_it = now
        if active.size == 0:
            break
        sub = op if active.size == B else op.subset(active)
        x, zE = it_.x[active], it_.zE[active]
        S, Z = [Sk[active] for Sk in it_.S], [Zk[active] for Zk in it_.Z]
        r = _residuals(sub, q[active], b[active], [bkk[active] for bkk in bk], x, zE, S, Z, lay)
        ok, diverged = stopping_rule(tol, r.pobj, r.dobj, rdx=np.einsum("bm,bm->b", r.rD, x), pres=r.pres,
                                     dres=r.dres, pscale=nb_inf[active] + r.xinf + r.sinf,
                                     dscale=nq_inf[active] + r.zinf, xzinf=np.maximum(r.xinf, r.zinf))
        # stalled: the merit has not halved over the last 4 iterations (the iterates sit on a face from
        # which the Newton direction makes no progress): hand over to the fallback
        merit = np.abs(r.pobj - r.dobj) + r.pres + r.dres
        stalled = stalled_rule(it, merit, history[active], flat_stall)
        history[active, :-1] = history[active, 1:]
        history[active, -1] = merit
        timeout = out_of_time(deadline, last)
        level = np.zeros(active.size, bool) if stop is None or it == 0 else \
            np.asarray(stop(active, it_, r), bool) & ~ok & ~diverged
        done = ok | diverged | stalled | (it == tol.ipm_max_iter) | timeout | level
        for j in np.nonzero(done)[0]:
            converged[active[j]] = bool(ok[j])
            finish([active[j]], it, IPM_LEVEL if level[j] else _why(ok[j], diverged[j], stalled[j], timeout))
        if done.all():
            break
        if done.any():
            active = active[~done]
            continue   # recompute on the compressed set (cheap) to keep the code single-path
        try:
            newton = _Newton(sub, S, Z, r, lay)
        except (np.linalg.LinAlgError, ValueError):
            finish(active, it, _SINGULAR)
            break
        newton.prepare()
        try:
            step = newton.predictor_corrector()
        except (np.linalg.LinAlgError, ValueError):
            finish(active, it, _SINGULAR)
            break
        _take_step(it_, active, x, zE, S, Z, step, tol.ipm_step_fraction)
    return it_, converged, its, tuple(reason)


def result_of(it_: Iterate, converged, its, reason, q, b, lay: Layout) -> IpmResult:
    """The :class:`IpmResult` of a finished batch in the standard form's row order."""
    B = q.shape[0]
    zfull = np.concatenate([it_.zE] + [svec(Zk) for Zk in it_.Z], axis=1)
    sfull = np.concatenate([np.zeros((B, lay.p))] + [svec(Sk) for Sk in it_.S], axis=1)
    pobj = np.einsum("bm,bm->b", q, it_.x)
    dobj = -np.einsum("br,br->b", b, zfull)
    return IpmResult(converged, it_.x, zfull, sfull, pobj, dobj, its, reason)


__all__ += ["result_of"]
