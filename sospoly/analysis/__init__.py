"""Reading a solved certificate: minimiser extraction (:mod:`.extraction`, :mod:`.sparse_extraction`),
certification by verification of quadratic programs (:mod:`.verify`) and the best such bound by ascent on the
Lagrangian dual (:mod:`.lagrangian`), complexity counts (:mod:`.complexity`) and
the feasible candidates of :func:`sospoly.minimize` (:mod:`.candidates`)."""

# The package face (:mod:`sospoly.faces`): callers outside sospoly import from ``sospoly.analysis``.
from ..faces import lazy_face

_MODULES = ('extraction', 'sparse_extraction', 'term_extraction', 'moments', 'verify', 'verify_sparse',
            'banded', 'rigor', 'proof', 'recession', 'complexity', 'candidates', 'lagrangian')

__getattr__, __dir__ = lazy_face(__name__, _MODULES, globals())
