"""Static checks of the package layering (issue #18 item 7), from the source text alone (no imports).

* no import cycle among module-level imports (``import`` statements at the top level of a module,
  including those inside a top-level ``if`` / ``try``), in sospoly and tritools, of any length;
* :mod:`sospoly.lowering` imports no :mod:`sospoly.solvers` module, anywhere (a solver consumes a lowered
  problem, never the reverse);
* tritools imports sospoly only through ``sospoly``, a sub-package's face (``sospoly.analysis``, never
  ``sospoly.analysis.verify``) and the top-level modules :mod:`sospoly.budget` and :mod:`sospoly.tolerances`;
* nothing in sospoly imports tritools;
* no sospoly module over 600 lines, no sospoly function over 80 lines, no sospoly class over 350 lines.
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sospoly", "tritools")
#: top-level sospoly modules (not packages) that tritools may import directly
SOSPOLY_PUBLIC_MODULES = ("sospoly.budget", "sospoly.tolerances")
MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_CLASS_LINES = 600, 80, 350


@functools.cache
def modules() -> dict:
    """Dotted module name -> (path, parsed tree) of every module of both packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = (path, ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
    return out


def imported(module: str, node: ast.AST, known) -> list:
    """The modules an import statement of ``module`` names: the target, and for ``from X import y``
    also ``X.y`` when that is a module (relative imports resolved against ``module``'s package)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        path, _ = known[module]
        base = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    return [target] + [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in known]


def _top_level_statements(body):
    """Statements run when the module is imported: the body, and the branches of top-level if/try."""
    for node in body:
        yield node
        if isinstance(node, ast.If):
            yield from _top_level_statements(node.body + node.orelse)
        elif isinstance(node, ast.Try):
            handlers = [s for h in node.handlers for s in h.body]
            yield from _top_level_statements(node.body + handlers + node.orelse + node.finalbody)


@functools.cache
def import_graph(module_level_only: bool) -> dict:
    """module -> set of imported modules of sospoly/tritools (module-level statements, or every import)."""
    known = modules()
    graph = {}
    for name, (_, tree) in known.items():
        nodes = _top_level_statements(tree.body) if module_level_only else ast.walk(tree)
        targets = set()
        for node in nodes:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                targets.update(imported(name, node, known))
        graph[name] = targets - {name}        # a package's `from . import sub` names the package itself
    return graph


def cycles(graph: dict) -> list:
    """The strongly connected components with more than one module (or a self-loop): Tarjan's algorithm,
    iterative.  Empty iff the graph has no cycle of any length."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root), on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w), on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1 or v in graph[v]:
                        out.append(sorted(comp))
    return out


# ---------------------------------------------------------------------------- the checker itself


def test_cycle_finder_finds_cycles_of_any_length_and_only_cycles():
    ring = {f"m{k}": {f"m{(k + 1) % 9}"} for k in range(9)}           # one cycle of length 9
    assert cycles(ring) == [sorted(ring)]
    chain = {f"m{k}": ({f"m{k + 1}"} if k < 8 else set()) for k in range(9)}
    assert cycles(chain) == []
    assert cycles({"a": {"a"}, "b": {"a"}}) == [["a"]]
    two = {"a": {"b"}, "b": {"a", "c"}, "c": {"d"}, "d": {"c"}, "e": {"a"}}
    assert sorted(cycles(two)) == [["a", "b"], ["c", "d"]]


def test_import_graph_sees_relative_absolute_and_package_imports():
    graph = import_graph(module_level_only=True)
    assert "sospoly.lowering.compiled" in graph["sospoly.solvers.compiled_solve"]     # from ..lowering.compiled
    assert "sospoly.lowering.conic" in graph["sospoly.lowering.compiled"]              # from .conic
    assert "sospoly" in graph["tritools.solve.structures"]                             # import sospoly
    lazy = import_graph(module_level_only=False)
    assert "sospoly.io.sdpa" in lazy["sospoly.lowering.conic"]                         # inside a method
    assert "sospoly.io.sdpa" not in graph["sospoly.lowering.conic"]


# ---------------------------------------------------------------------------- the layering


def test_no_import_cycle_among_module_level_imports():
    found = cycles(import_graph(module_level_only=True))
    assert not found, f"import cycles: {found}"


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def lowering_to_solvers(graph: dict) -> list:
    """(module, import) pairs where sospoly.lowering imports sospoly.solvers."""
    return [(m, t) for m, ts in graph.items() if _in(m, "sospoly.lowering") for t in sorted(ts)
            if _in(t, "sospoly.solvers")]


def deep_sospoly_imports(graph: dict, faces: set) -> list:
    """(module, import) pairs where tritools imports a sospoly module that is not one of ``faces``."""
    return sorted((m, t) for m, ts in graph.items() if _in(m, "tritools") for t in ts
                  if _in(t, "sospoly") and t not in faces)


def sospoly_to_tritools(graph: dict) -> list:
    return [(m, t) for m, ts in graph.items() if _in(m, "sospoly") for t in sorted(ts) if _in(t, "tritools")]


def _sospoly_faces() -> set:
    """``sospoly``, its sub-packages (directories with an ``__init__``) and the public top-level modules."""
    subpackages = {m for m, (p, _) in modules().items() if m.startswith("sospoly.") and m.count(".") == 1
                   and p.name == "__init__.py"}
    return {"sospoly"} | subpackages | set(SOSPOLY_PUBLIC_MODULES)


def test_layering_rules_flag_violations():
    bad = {"sospoly.lowering.compiled": {"sospoly.solvers.ipm", "sospoly.algebra.svec"},
           "sospoly.lowering": {"sospoly.solvers"}, "sospoly.lowering_extra": {"sospoly.solvers.solve"},
           "tritools.model.stacked": {"sospoly", "sospoly.analysis", "sospoly.analysis.verify", "sospoly.budget"},
           "sospoly.analysis.rigor": {"tritools.result", "sospoly.algebra"}, "tritoolsx": {"sospoly.analysis.rigor"}}
    assert lowering_to_solvers(bad) == [("sospoly.lowering.compiled", "sospoly.solvers.ipm"),
                                        ("sospoly.lowering", "sospoly.solvers")]
    assert deep_sospoly_imports(bad, _sospoly_faces()) == [("tritools.model.stacked", "sospoly.analysis.verify")]
    assert sospoly_to_tritools(bad) == [("sospoly.analysis.rigor", "tritools.result")]


def test_lowering_imports_no_solver():
    bad = lowering_to_solvers(import_graph(module_level_only=False))
    assert not bad, f"sospoly.lowering imports solvers: {bad}"


def test_tritools_imports_sospoly_only_through_its_faces():
    faces = _sospoly_faces()
    assert {"sospoly.analysis", "sospoly.solvers", "sospoly.budget"} <= faces
    assert "sospoly.analysis.verify" not in faces and "sospoly.minimize" not in faces
    bad = deep_sospoly_imports(import_graph(module_level_only=False), faces)
    assert not bad, f"tritools reaches into sospoly internals: {bad}"


def test_nothing_in_sospoly_imports_tritools():
    bad = sospoly_to_tritools(import_graph(module_level_only=False))
    assert not bad, f"sospoly imports tritools: {bad}"


# ---------------------------------------------------------------------------- sizes


def _sospoly_modules():
    return [(m, p, tree) for m, (p, tree) in modules().items() if m.split(".")[0] == "sospoly"]


def test_no_sospoly_module_over_600_lines():
    long = {m: n for m, p, _ in _sospoly_modules()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


@pytest.mark.parametrize("kind, limit", [(ast.FunctionDef, MAX_FUNCTION_LINES), (ast.ClassDef, MAX_CLASS_LINES)],
                         ids=["functions", "classes"])
def test_no_long_function_or_class_in_sospoly(kind, limit):
    long = {f"{m}.{n.name}": n.end_lineno - n.lineno + 1 for m, _, tree in _sospoly_modules()
            for n in ast.walk(tree) if isinstance(n, (kind, ast.AsyncFunctionDef) if kind is ast.FunctionDef
                                                  else kind) and n.end_lineno - n.lineno + 1 > limit}
    assert not long, f"over {limit} lines: {long}"
