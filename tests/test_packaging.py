"""Packaging: a LICENSE, ``py.typed`` markers installed with both packages, and sympy / cvxpy out of the
required dependencies (optional extras, still pulled in by the ``test`` extra so CI runs their tests)."""
import ast
import pathlib
import re
import tomllib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
OPTIONAL = ("sympy", "cvxpy")


def _names(reqs):
    return {re.split(r"[<>=\[ ;]", r, maxsplit=1)[0].lower() for r in reqs}


def test_license_file_is_mit_as_declared():
    text = (ROOT / "LICENSE").read_text()
    assert PYPROJECT["project"]["license"] == "MIT"
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def test_py_typed_in_both_packages_and_in_package_data():
    for pkg in ("sospoly", "tritools"):
        assert (ROOT / pkg / "py.typed").is_file(), pkg
        assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"][pkg], pkg


def test_sympy_and_cvxpy_are_optional_but_installed_for_tests():
    project = PYPROJECT["project"]
    required = _names(project["dependencies"])
    extras = project["optional-dependencies"]
    for name in OPTIONAL:
        assert name not in required, name
        assert name in _names(extras[name]), name
        assert name in _names(extras["test"]), f"the test extra must install {name} so CI runs its tests"
    assert any(c.startswith("Typing ::") for c in project["classifiers"])


def test_every_sympy_and_cvxpy_import_is_lazy():
    """No module of either package imports sympy or cvxpy at import time (only inside functions)."""
    for path in list((ROOT / "sospoly").rglob("*.py")) + list((ROOT / "tritools").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in tree.body:                                   # module level only
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in OPTIONAL for n in names), f"{path}: {names}"


def test_sympy_converters_without_sympy_say_how_to_install(monkeypatch):
    import builtins

    from sospoly import variables

    real = builtins.__import__

    def no_sympy(name, *a, **k):
        if name == "sympy" or name.startswith("sympy."):
            raise ImportError("No module named 'sympy'")
        return real(name, *a, **k)

    x, = variables("x")
    monkeypatch.setattr(builtins, "__import__", no_sympy)
    with pytest.raises(ImportError, match=r"sospoly-tritools\[sympy\]"):
        (x + 1).to_sympy()
    assert (x**2 + 1)(2.0) == 5.0                                # the rest works without sympy


def test_the_top_level_api_is_fully_annotated():
    """Every function exported by ``tritools`` (and the pycolmap bridge) annotates all its parameters and return."""
    import inspect

    import sospoly
    import tritools
    import tritools.io.colmap.pycolmap_bridge as bridge

    funcs = [getattr(tritools, n) for n in tritools.__all__ if inspect.isfunction(getattr(tritools, n))]
    funcs += [bridge.from_pycolmap, bridge.to_pycolmap, sospoly.minimize, sospoly.is_sos]
    for f in funcs:
        sig = inspect.signature(f)
        missing = [p.name for p in sig.parameters.values()
                   if p.annotation is inspect.Parameter.empty and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]
        assert not missing and sig.return_annotation is not inspect.Signature.empty, (f.__name__, missing)
