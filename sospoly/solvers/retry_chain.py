"""The settings Clarabel is tried with, in order, and the constants of the retry chain's rules
(:meth:`sospoly.solvers.backends.ClarabelBackend.solve`)."""
from __future__ import annotations

__all__ = ["CLARABEL_RETRY_CHAIN", "CLARABEL_FAST_CHAIN", "CLARABEL_SPLIT_CHAIN", "QDLDL_MAX_PSD_SIDE",
           "RETRY_MIN_ITERATIONS"]

#: Settings tried in order when an attempt fails numerically (label, overrides).
CLARABEL_RETRY_CHAIN = (
    ("default", {}),
    ("qdldl", {"direct_solve_method": "qdldl"}),
    ("no-equilibration", {"direct_solve_method": "qdldl", "equilibrate_enable": False}),
    ("regularised", {"direct_solve_method": "qdldl", "equilibrate_enable": False,
                     "static_regularization_constant": 1e-7, "max_iter": 1000}),
)

#: :data:`CLARABEL_RETRY_CHAIN` after a first attempt without iterative refinement of the KKT solves (Clarabel's
#: refinement steps cost about as much as the factorisation on programs of many PSD blocks: a 16-view clique
#: program 15.3 -> 8.4 s, a 30-view degree-2 program 4.6 -> 2.9 s, same iterations and objectives).  The first
#: attempt is *provisional*: only a SOLVED answer (every tolerance met on Clarabel's own residuals) or the time
#: limit ends the chain there; anything else goes on to the refined attempts.
CLARABEL_FAST_CHAIN = (("no-refinement", {"iterative_refinement_enable": False}),) + CLARABEL_RETRY_CHAIN

#: :data:`CLARABEL_RETRY_CHAIN` after a first attempt whose chordal decomposition keeps the cliques of a large
#: sparse-patterned PSD block apart instead of merging them into compact ones (``chordal_decomposition_compact``
#: off).  Measured on dense degree-2 programs with mixed regions (one block of side 2N + sum n_i + 1; 6
#: programs at N = 16 and 30, CPU): 13-18 instead of 21-32 iterations, 0.23-3.4 s instead of 0.27-6.1 s, and
#: "solved" where the default ended "almost solved" (4 of 6).  Not a provisional attempt: its answers are judged
#: like the default's.  On a many-block views program it was slower (7.2 -> 15.1 s): not used there.
CLARABEL_SPLIT_CHAIN = (("split-cliques", {"chordal_decomposition_compact": False}),) + CLARABEL_RETRY_CHAIN

#: the retries' ``qdldl`` factorisation is used only while every PSD block has at most this side; beyond it
#: the KKT fill-in makes one qdldl iteration take tens of seconds (one 77-sided block: 40 s, where the
#: default faer factorisation takes 1 s), and no time limit can interrupt it, so the retries keep faer.
QDLDL_MAX_PSD_SIDE = 40

#: a retry is taken to need the iterations of the attempt it repeats, up to this many, at that attempt's pace
#: (:func:`sospoly.solvers.backends._repeat_seconds`; Clarabel takes 15-30 on the SOS programs here)
RETRY_MIN_ITERATIONS = 20
