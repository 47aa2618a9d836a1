"""``import tritools`` (every command-line call pays it) and a point triangulation do not import networkx or
scipy.optimize (~0.5 s together): sparsity graphs and linear programs load them on first use."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import sys
import numpy as np
import tritools
from tritools.scene import random_scene
loaded = lambda: sorted(m for m in ("networkx", "scipy.optimize") if m in sys.modules)
print("import", loaded())
sc = random_scene(4, 3, 1.0, seed=1)
tritools.triangulate(sc.cameras, sc.points2d[0])
tritools.triangulate(sc.cameras, sc.points2d[1], robust=3.0)
tritools.triangulate_many([(sc.cameras, sc.points2d[j]) for j in range(3)])
print("points", loaded())
from sospoly.certificates.sparsity import chordal_extension, csp_graph
G = chordal_extension(csp_graph(3, np.array([[1, 1, 0], [0, 1, 1]])))
print("graph", loaded(), sorted(G.edges()))
"""


def test_import_and_point_calls_load_no_graph_or_lp_library():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, cwd=ROOT, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "import []" and lines[1] == "points []", out.stdout
    assert lines[2].startswith("graph ['networkx']") and "(0, 1)" in lines[2], out.stdout   # loaded on first use


def test_the_lazy_module_copies_and_pickles():
    import copy
    import pickle

    from sospoly.certificates import sparsity

    assert type(copy.copy(sparsity.nx)).__name__ == "_OnFirstUse"
    assert pickle.loads(pickle.dumps(sparsity.nx)).Graph is not None
