"""The ``tritools`` command line (tritools.cli.app) and its problem-file schema (tritools.io.problem_file).

References: the paper's Table 10 (Example 4, 3 decimals), scenes built so that every region
contains the exact projections of a known point (gamma* = 0), and exact error messages.
"""
import importlib.metadata
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from tests.cli_util import run, write
from tritools.cli import app as cli
from tritools.model.geometry import image_points
from tritools.io.problem_file import (ProblemFileError, parse_problem_text, parse_problems, problem_to_dict,
                                   problems_to_json, result_from_dict, result_to_dict)
from tritools.model.regions import Ellipse, EllipseBorder, Point, Polytope, Segment
from tritools.scene import paper_example, paper_table, random_scene

#: the paper prints 3 decimals: agreement to half a unit of the last digit (+ float slack).
PAPER_ATOL = 5e-4 + 1e-9
#: gamma* = 0 scenes: a certified optimum must have gamma_UB ~ 0 (the solver reaches ~1e-8 in c).
ZERO_GAMMA_ATOL = 1e-5






def example4_doc(name="ex4", **overrides):
    cams, regions = paper_example(4)
    return problem_to_dict(cams, regions, name, **overrides)


def mixed_doc():
    """Example 2's cameras; a segment, a filled ellipse and a polytope, each containing the
    exact projection of X0 (so gamma* = 0), written by hand in the schema's JSON form."""
    cams, _ = paper_example(2)
    X0 = np.array([-0.815, -0.07, 0.793])
    x = image_points(X0, cams)
    regions = [{"type": "segment", "center": (x[0] + [0.1, 0.05]).tolist(), "direction": [0.2, 0.1]},
               {"type": "ellipse", "center": (x[1] + [0.05, 0.0]).tolist(), "D": [[0.04, 0.0], [0.0, 0.01]]},
               {"type": "polytope", "B": [[5.0, 0.0], [0.0, 5.0], [3.0, 3.0]],
                "c": [-5 * x[2][0], -5 * x[2][1], -3 * (x[2][0] + x[2][1])]}]
    return {"name": "mixed", "cameras": cams.tolist(), "regions": regions}


# ----------------------------------------------------------------------------- solve: results
def test_solve_example4_json_matches_paper_and_round_trips(tmp_path, capsys):
    path = write(tmp_path, example4_doc())
    rc, out, err = run(["solve", path, "--method", "theorem1", "--delta", "4", "--json"], capsys)
    assert rc == 0, err
    rows = json.loads(out)
    assert len(rows) == 1 and rows[0]["name"] == "ex4" and rows[0]["n_views"] == 4
    paper = next(r for r in paper_table(4) if r["method"] == "theorem1" and r.get("delta") == 4)
    r = rows[0]
    assert r["status"] == "optimal" and r["optimal"] is True and r["delta"] == 4
    assert r["n_lmivar"] == paper["n_lmivar"] == 591
    np.testing.assert_allclose(r["X"], paper["X"], atol=PAPER_ATOL)
    assert abs(r["gamma_ub"] - paper["gamma"]) <= PAPER_ATOL
    assert abs(r["gamma_lb"] - paper["gamma"]) <= PAPER_ATOL
    # round trip: JSON -> TriangulationResult -> JSON is the identity
    res = result_from_dict(r)
    assert res.status.value == "optimal" and res.X.shape == (3,)
    again = result_to_dict(res, index=0, name="ex4", n_views=4)
    assert json.loads(json.dumps(again)) == r


def test_solve_user_written_mixed_regions(tmp_path, capsys):
    doc = mixed_doc()
    path = write(tmp_path, doc)
    rc, out, err = run(["solve", path, "--method", "corollary1", "--delta", "2", "--json"], capsys)
    assert rc == 0, err
    (r,) = json.loads(out)
    assert r["status"] == "optimal" and r["gamma_ub"] <= ZERO_GAMMA_ATOL
    # independent check: the projections of X lie in every region (distance ~ 0)
    cams = np.array(doc["cameras"])
    regions = [Segment(**{k: v for k, v in doc["regions"][0].items() if k != "type"}),
               Ellipse(doc["regions"][1]["center"], doc["regions"][1]["D"]),
               Polytope(doc["regions"][2]["B"], doc["regions"][2]["c"])]
    x = image_points(np.array(r["X"]), cams)
    assert max(reg.distance(p) for reg, p in zip(regions, x)) <= ZERO_GAMMA_ATOL * np.sqrt(6)
    # the human-readable table names the columns and shows the row
    rc, out, err = run(["solve", path, "--method", "corollary1", "--delta", "2"], capsys)
    assert rc == 0, err
    header, rule, row = out.strip().splitlines()[:3]          # then notes (here: the point is behind camera 1)
    for col in ("name", "N", "status", "X", "gamma_LB", "gamma_UB", "optimal", "delta", "N_LMIVAR", "time[s]"):
        assert col in header.split()
    assert row.split()[:3] == ["mixed", "3", "optimal"] and " yes " in row


def test_list_file_bad_problem_gets_status_row_and_overrides_apply(tmp_path, capsys):
    cams, _ = paper_example(4)
    same = {"name": "same", "cameras": [cams[0].tolist()] * 3, "regions": [[0.1, 0.2]] * 3}
    path = write(tmp_path, [example4_doc(method="corollary1", delta=2), same])   # a bare list
    rc, out, err = run(["solve", path, "--method", "theorem1", "--json"], capsys)
    assert rc == 0, err
    good, bad = json.loads(out)
    assert (good["method"], good["delta"]) == ("corollary1", 2)                  # per-problem overrides
    assert good["status"] == "not_certified"            # Table 10: Corollary 1 at delta 2 does not certify
    assert abs(good["gamma_lb"] - 0.729) <= PAPER_ATOL  # our gamma_LB for that row (tritools example 4)
    assert bad["status"] == "ill_posed" and "equal" in bad["message"] and bad["X"] is None
    rc, out, err = run(["solve", path], capsys)
    assert rc == 0
    lines = out.strip().splitlines()
    assert lines[3].split()[:3] == ["same", "3", "ill_posed"]
    assert lines[-1].startswith("same: ill_posed: ") and "equal up to scale" in lines[-1]


def test_solve_output_file_and_stdin(tmp_path, capsys, monkeypatch):
    text = json.dumps({"problems": [example4_doc(method="corollary1", delta=2)]})
    monkeypatch.setattr(sys, "stdin", __import__("io").StringIO(text))
    out_path = tmp_path / "out.json"
    rc, out, err = run(["solve", "-", "--json", "--output", out_path], capsys)
    assert rc == 0 and out == "" and err == ""
    (r,) = json.loads(out_path.read_text())
    assert r["name"] == "ex4" and r["delta"] == 2


# ----------------------------------------------------------------------------- solve: bad files
def _ex4_with(mutate, wrap=False):
    doc = example4_doc()
    mutate(doc)
    return {"problems": [example4_doc(), doc]} if wrap else doc


BAD_FILES = {
    "not_pd": (_ex4_with(lambda d: d["regions"].__setitem__(0, {"type": "ellipse", "center": [0, 0],
                                                                  "D": [[1, 0], [0, -1]]}), wrap=True),
               "problems[1].regions[0].D: must be positive definite"),
    "camera_shape": (_ex4_with(lambda d: d["cameras"].__setitem__(2, [[1, 0, 0]] * 3)),
                     "cameras[2]: expected shape (3, 4), got (3, 3)"),
    "unknown_type": (_ex4_with(lambda d: d["regions"].__setitem__(0, {"type": "circle", "center": [0, 0]})),
                     "regions[0].type: unknown region type 'circle' (expected point, segment, polytope, "
                     "ellipse_border, ellipse"),   # (+ any types registered by other code)
    "missing_region_field": (_ex4_with(lambda d: d["regions"][1].pop("x")), "regions[1].x: missing required field"),
    "missing_type": (_ex4_with(lambda d: d["regions"][3].pop("type")), "regions[3].type: missing required field"),
    "missing_cameras": (_ex4_with(lambda d: d.pop("cameras")), "cameras: missing required field"),
    "count": (_ex4_with(lambda d: d["regions"].pop()), "regions: expected one region per camera (4), got 3"),
    "one_camera": ({"cameras": [np.eye(3, 4).tolist()], "regions": [[0, 0]]}, "cameras: at least 2 cameras"),
    "nan": (json.dumps(example4_doc()).replace("0.8", "NaN", 1), "regions[0].x[0]: non-finite number NaN"),
    "infinity": (json.dumps({"problems": [example4_doc()]}).replace('"x": [0.4', '"x": [-Infinity', 1),
                 "problems[0].regions[1].x[0]: non-finite number -Infinity"),
    "huge": (json.dumps(example4_doc()).replace('"x": [0.4', '"x": [1e999', 1), "regions[1].x[0]: non-finite"),
    "string_number": (_ex4_with(lambda d: d["cameras"][1][2].__setitem__(3, "1")),
                      "cameras[1][2][3]: expected a number, got string '1'"),
    "ragged": (_ex4_with(lambda d: d["regions"].__setitem__(0, {"type": "polytope", "B": [[1, 0], [0]],
                                                                  "c": [0, 0]})),
               "regions[0].B: must be a numeric matrix, got [[1, 0], [0]]"),
    "segment_shape": (_ex4_with(lambda d: d["regions"].__setitem__(2, {"type": "segment", "center": [1, 2, 3],
                                                                         "direction": [0, 1]})),
                      "regions[2].center: must have shape (2,), got (3,)"),
    "unbounded_polytope": (_ex4_with(lambda d: d["regions"].__setitem__(0, {"type": "polytope",
                                                                              "B": [[1, 0], [2, 0]], "c": [0, 0]})),
                           "regions[0].B: has rank < 2"),
    "typo_field": (_ex4_with(lambda d: d.__setitem__("delat", 4)), "delat: unknown field"),
    # solver settings: the rules (and words) of TriangulationOptions, the one validation of the flags too
    "odd_delta": (_ex4_with(lambda d: d.__setitem__("delta", 3)), "delta: must be an even integer >= 2, got 3"),
    "bad_method": (_ex4_with(lambda d: d.__setitem__("method", "newton")),
                   "method: must be one of 'auto', 'theorem1', 'corollary1', got 'newton'"),
    "empty": ({"problems": []}, "problems: no problems"),
    "top_level": ("42", "$: expected a problem object, an array of problems"),
    "not_json": ('{"cameras": [1, 2', "not valid JSON: Expecting"),
    # an integer literal beyond the float range used to escape as an internal OverflowError (exit 1)
    "huge_integer": (json.dumps(example4_doc()).replace('"x": [0.4', '"x": [1' + "0" * 400, 1),
                     "regions[1].x[0]: integer with 401 digits is too large"),
}


@pytest.mark.parametrize("kind", sorted(BAD_FILES))
def test_bad_file_exit_2_one_line_naming_the_field(kind, tmp_path, capsys):
    doc, expected = BAD_FILES[kind]
    path = write(tmp_path, doc)
    rc, out, err = run(["solve", path], capsys)
    assert rc == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("tritools: error: "), err
    assert expected in err, err
    if kind == "not_json":
        assert str(path) in err


def test_unreadable_file(tmp_path, capsys):
    rc, out, err = run(["solve", tmp_path / "missing.json"], capsys)
    missing = tmp_path / "missing.json"
    assert rc == 2 and err.strip() == f"tritools: error: {missing}: cannot read: No such file or directory"


def test_bad_arguments_one_line(tmp_path, capsys):
    rc, _, err = run(["solve", write(tmp_path, example4_doc()), "--method", "newton"], capsys)
    assert rc == 2 and len(err.splitlines()) == 1 and "--method: invalid choice: 'newton'" in err
    rc, _, err = run([], capsys)
    assert rc == 2 and "required: COMMAND" in err


def test_internal_error_one_line_or_traceback_when_debugging(tmp_path, capsys, monkeypatch):
    def boom(*a, **k):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(cli, "_timed_solve", boom)
    path = write(tmp_path, example4_doc())
    rc, _, err = run(["solve", path], capsys)
    assert rc == 1
    assert err.strip() == "tritools: internal error: RuntimeError: kaboom (set TRITOOLS_DEBUG=1 for the traceback)"
    monkeypatch.setenv("TRITOOLS_DEBUG", "1")
    with pytest.raises(RuntimeError, match="kaboom"):
        cli.main(["solve", str(path)])


# ----------------------------------------------------------------------------- schema round trip
def test_schema_round_trip_every_region_type():
    cams, _ = paper_example(4)
    regions = [Point([0.8, 0.2]), Segment([0.4, 0.8], [0.1, 0.0]),
               Polytope([[10.0, 0.0], [0.0, 10.0]], [-6.0, -18.0]), Ellipse([1.0, 0.2], [[0.01, 0], [0, 0.02]])]
    text = problems_to_json([problem_to_dict(cams, regions, "a", method="corollary1", delta=2, path="auto"),
                             problem_to_dict(cams[:3], [EllipseBorder([0, 0], np.eye(2)), [1, 2], [3, 4]])])
    a, b = parse_problem_text(text)
    assert a.regions == tuple(regions) and np.array_equal(a.cameras, cams)
    assert (a.name, a.method.value, a.delta, a.max_delta, a.path.value) == ("a", "corollary1", 2, None, "auto")
    assert b.regions == (EllipseBorder([0, 0], np.eye(2)), Point([1, 2]), Point([3, 4])) and b.name is None
    with pytest.raises(ProblemFileError, match=r"^problems\[0\]\.regions\[0\]\[1\]: non-finite"):
        parse_problems({"problems": [{"cameras": cams.tolist(), "regions": [[0, float("nan")]] * 4}]})


# ----------------------------------------------------------------------------- example
def test_example5_reduced(capsys, monkeypatch):
    monkeypatch.setattr(cli, "EXAMPLE5_THETAS", (0.05,))      # one case: 1 point x 1 theta x 1 trial
    rc, out, err = run(["example", "5", "--points", "1", "--trials", "1", "--json"], capsys)
    assert rc == 0, err
    d = json.loads(out)
    (row,) = d["per_theta"]
    # the paper certifies every case at theta = 0.05 (Table 11), and so do we (benchmarks/RESULTS.md)
    assert (row["theta"], row["cases"], row["certified"], row["n_lmivar"]) == (0.05, 1, 1, [591])
    assert "python benchmarks/paper_examples.py --only-example5" in d["note"]
    rc, _, err = run(["example", "5", "--points", "0"], capsys)
    assert rc == 2 and "--points must be a positive integer" in err


# ----------------------------------------------------------------------------- dataset
def _toy_sequence(root, name="toy"):
    """A VGG-format sequence of 3 exact views of 4 points; the last point is missing in view 2."""
    scene = random_scene(3, 4, noise_px=0.0, seed=7)
    folder = root / name
    folder.mkdir(parents=True)
    for v, P in enumerate(scene.cameras):
        np.savetxt(folder / f"{name}.{v:03d}.P", P)
        np.savetxt(folder / f"{name}.{v:03d}.corners", scene.points2d_true[:, v, :])
    rows = [" ".join(str(j) for _ in range(3)) for j in range(4)]
    rows[3] = "3 3 *"
    (folder / f"{name}.nview-corners").write_text("\n".join(rows) + "\n")
    return scene


def test_dataset_on_a_toy_sequence(tmp_path, capsys):
    scene = _toy_sequence(tmp_path)
    csv_path = tmp_path / "tracks.csv"
    rc, out, err = run(["dataset", "toy", "--data-dir", tmp_path, "--json", "--csv", csv_path], capsys)
    assert rc == 0, err
    d = json.loads(out)
    assert [(s["N"], s["cases"], s["certified"]) for s in d["per_N"]] == [(2, 1, 1), (3, 3, 3)]
    assert d["total"]["cases"] == 4 and d["total"]["mean_gamma_ub"] <= ZERO_GAMMA_ATOL
    import csv
    rows = list(csv.DictReader(csv_path.open()))
    assert len(rows) == 4
    for row in rows:           # exact projections: the estimate is the true point (gamma* = 0, unique)
        X = np.array([float(row[k]) for k in ("X1", "X2", "X3")])
        np.testing.assert_allclose(X, scene.points3d[int(row["track_id"])], atol=1e-5)
    rc, out, err = run(["dataset", "toy", "--data-dir", tmp_path, "--limit", "2"], capsys)
    assert rc == 0 and out.splitlines()[0] == "toy: 2 tracks, method auto"
    assert out.splitlines()[-1].split()[:3] == ["total", "2", "2"]


def test_dataset_missing_data_dir(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TRITOOLS_DATA", raising=False)
    rc, out, err = run(["dataset", "library", "--data-dir", tmp_path / "nowhere"], capsys)
    assert rc == 2 and len(err.splitlines()) == 1
    assert str(tmp_path / "nowhere") in err and "--data-dir" in err and "$TRITOOLS_DATA" in err
    monkeypatch.setenv("TRITOOLS_DATA", str(tmp_path / "env_nowhere"))
    rc, out, err = run(["dataset", "library"], capsys)
    assert rc == 2 and str(tmp_path / "env_nowhere") in err


# ----------------------------------------------------------------------------- registry and entry points
def test_subcommand_registry(tmp_path, capsys, monkeypatch):
    (tmp_path / "hello_cli.py").write_text(
        "def register(sub):\n"
        "    p = sub.add_parser('hello')\n"
        "    p.set_defaults(func=lambda args: 3)\n")
    (tmp_path / "broken_cli.py").write_text("import no_such_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(cli, "SUBCOMMAND_MODULES", ("hello_cli", "tritools.no_such_cli_yet"))
    assert cli.main(["hello"]) == 3                      # registered; the missing module is skipped
    monkeypatch.setattr(cli, "SUBCOMMAND_MODULES", ("broken_cli",))
    rc, _, err = run(["hello"], capsys)                  # a missing *dependency* is not hidden
    assert rc == 1 and "ModuleNotFoundError" in err and "no_such_dependency_xyz" in err


def test_python_m_and_console_script_dispatch():
    env = dict(os.environ, RUST_BACKTRACE="0")
    p = subprocess.run([sys.executable, "-m", "tritools", "--help"], capture_output=True, text=True, env=env,
                       timeout=60)
    assert p.returncode == 0 and "solve" in p.stdout and "dataset" in p.stdout and "example" in p.stdout
    (ep,) = [e for e in importlib.metadata.entry_points(group="console_scripts") if e.name == "tritools"]
    assert ep.value == "tritools.__main__:main" and ep.load() is cli.main
    script = shutil.which("tritools", path=os.path.dirname(sys.executable))
    if script:                                            # installed (editable) console script
        p = subprocess.run([script, "solve", "--help"], capture_output=True, text=True, env=env, timeout=60)
        assert p.returncode == 0 and "FILE" in p.stdout


def test_docs_json_examples_follow_the_schema():
    import pathlib
    import re

    text = (pathlib.Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text()
    blocks = re.findall(r"^```json\n(.*?)^```", text, re.S | re.M)
    assert blocks
    for block in blocks:
        specs = parse_problem_text(block)
        assert all(s.n_views == len(s.cameras) for s in specs)


def test_overflowing_input_prints_no_numpy_warnings(tmp_path, capsys):
    # finite but extreme numbers overflow inside numpy; its RuntimeWarnings used to add lines to the
    # one-line error (exit 2) and to the output of a solve whose bad problem gets a status row (exit 0)
    import warnings

    bad_d = _ex4_with(lambda d: d["regions"].__setitem__(0, {"type": "ellipse", "center": [0, 0],     # not PD
                                                             "D": [[1e308, 1e307], [1e307, -1e308]]}))
    huge_point = {"cameras": [np.eye(3, 4).tolist(), [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 0]]],
                  "regions": [[1e308, 1e308], [0.5, 0.0]]}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rc, out, err = run(["solve", write(tmp_path, bad_d)], capsys)
        assert rc == 2 and len(err.splitlines()) == 1 and "regions[0].D" in err, err
        rc, out, err = run(["solve", write(tmp_path, huge_point, "huge.json"), "--method", "corollary1",
                            "--delta", "2", "--path", "auto", "--json"], capsys)
        assert rc == 0 and err == "", err
        assert json.loads(out)[0]["status"] != "optimal"
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]


def test_a_negative_non_number_value_gets_the_flag_s_own_message(tmp_path, capsys):
    """Review 22a F4: ``--robust -inf`` said argparse's "expected one argument" (``-inf`` read as an option); the
    value now reaches the flag's own check, as ``--robust=-inf`` did.  Exit 2, one line naming the flag."""
    problems = str(write(tmp_path, example4_doc()))
    for value in ("-inf", "-nan", "-1e5"):
        assert cli.main(["solve", problems, "--robust", value]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--robust" in err and "expected one argument" not in err, err
    assert cli._joined_negative_values(["solve", "f.json", "--robust", "-inf", "--json"]) == \
        ["solve", "f.json", "--robust=-inf", "--json"]
    assert cli._joined_negative_values(["--robust", "--json", "-o", "-x"]) == ["--robust", "--json", "-o", "-x"]
