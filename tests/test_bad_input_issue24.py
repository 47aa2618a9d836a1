"""Issue 24, defects 8 and 9: bad input is refused by name, and names cannot drive the terminal.

* region fields refuse booleans (``[True, 0]`` was read as ``[1.0, 0.0]``), as cameras do;
* integers beyond int64 are read as the floats they are, and beyond the float range refused by name
  (they were refused as "got object");
* a duplicated JSON key is refused with the key and the line (the earlier value was dropped);
* a 30-digit COLMAP WIDTH exits 2 (was 1: OverflowError); a non-UTF-8 byte in cameras.txt is
  reported at file:line;
* a problem name holding terminal escape sequences is printed escaped in the table.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from tests.cli_util import run, write
from tests.test_cli import example4_doc
from tritools.io.colmap import write_model_arrays
from tritools.io.problem_file import ProblemFileError, parse_problem_text
from tritools.model.geometry import validate_cameras
from tritools.model.regions import Region, as_regions
from tritools.sfm.synthetic import synthetic_arrays


@pytest.mark.parametrize("d, field", [
    ({"type": "ellipse", "center": [True, 0], "D": [[1, 0], [0, 1]]}, "center"),
    ({"type": "ellipse", "center": [0, 0], "D": [[1, 0], [0, True]]}, "D"),
    ({"type": "point", "x": [1.5, False]}, "x"),
])
def test_region_fields_refuse_booleans(d, field):
    with pytest.raises(ValueError, match=f"{field} must be real numbers, got bool"):
        Region.from_dict(d)
    with pytest.raises(ValueError, match="must be real numbers, got bool"):
        as_regions([[True, 0.0], [0.0, 1.0]])


def test_cameras_refuse_booleans_in_nested_lists():
    P = np.eye(3, 4).tolist()
    P[0][0] = True
    with pytest.raises(ValueError, match="cameras must be real numbers, got bool"):
        validate_cameras([P, (np.eye(3, 4) + 0.1).tolist()])


def test_integers_beyond_int64_are_numbers_or_named():
    r = Region.from_dict({"type": "ellipse", "center": [10 ** 20, 0], "D": [[1, 0], [0, 1]]})
    assert r.center.tolist() == [1e20, 0.0]                    # was "center must be real numbers, got object"
    with pytest.raises(ValueError, match=r"center: an integer of about 401 digits is beyond the floating-point"):
        Region.from_dict({"type": "ellipse", "center": [10 ** 400, 0], "D": [[1, 0], [0, 1]]})


def test_duplicated_json_keys_are_refused_with_key_and_line():
    text = json.dumps({"problems": [example4_doc(delta=4), example4_doc(delta=4)]}, indent=1)
    i = text.rindex('"delta": 4')
    bad = text[:i] + '"delta": 3,\n  "delta": 4' + text[i + len('"delta": 4'):]
    line = bad[:bad.rindex('"delta": 4')].count("\n") + 1
    with pytest.raises(ProblemFileError) as info:
        parse_problem_text(bad, "p.json")
    assert str(info.value) == f"p.json:{line}: duplicated key 'delta' (each field may appear once)"
    assert parse_problem_text(text, "p.json")[1].delta == 4    # the valid file still reads


def test_duplicated_key_through_the_cli(tmp_path, capsys):
    p = write(tmp_path, '{"cameras": [], "cameras": []}')
    rc, _, err = run(["solve", p], capsys)
    assert rc == 2 and err == f"tritools: error: {p}:1: duplicated key 'cameras' (each field may appear once)\n"


@pytest.fixture()
def text_model(tmp_path):
    a, _ = synthetic_arrays(n_points=10, n_images=4, camera="PINHOLE", seed=1)
    write_model_arrays(a, tmp_path / "in", "txt")
    return tmp_path / "in"


def _edit_line(path, k, edit):
    lines = path.read_bytes().split(b"\n")
    lines[k] = edit(lines[k])
    path.write_bytes(b"\n".join(lines))


def test_a_30_digit_colmap_width_exits_2(text_model, tmp_path, capsys):
    _edit_line(text_model / "cameras.txt", 3, lambda b: b.replace(b" 1024 ", b" " + b"9" * 30 + b" ", 1))
    rc, _, err = run(["colmap", text_model, tmp_path / "out"], capsys)
    assert rc == 2 and err.startswith("tritools: error: cameras.txt:4: WIDTH 9999") and "64-bit" in err, err


@pytest.mark.parametrize("k, col", [(3, 5), (1, 3)])
def test_non_utf8_in_cameras_txt_names_file_and_line(text_model, tmp_path, capsys, k, col):
    _edit_line(text_model / "cameras.txt", k, lambda b: b[:col - 1] + b"\xff" + b[col - 1:])
    rc, _, err = run(["colmap", text_model, tmp_path / "out"], capsys)
    assert rc == 2 and err == f"tritools: error: cameras.txt:{k + 1}: not UTF-8 text (byte 0xff at column {col})\n"


def test_names_with_terminal_escapes_are_escaped_in_the_table(tmp_path, capsys):
    name = "evil\x1b[2J\x1b]0;title\x07\u202eok é"
    rc, out, _ = run(["solve", write(tmp_path, example4_doc(name=name))], capsys)
    assert rc == 0 and "\x1b" not in out and "\x07" not in out and "\u202e" not in out
    assert "evil\\x1b[2J\\x1b]0;title\\x07\\u202eok é" in out     # visible, printable text kept
