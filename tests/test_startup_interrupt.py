"""Issue 24, defect 10: Ctrl-C while ``tritools`` starts (importing numpy, scipy, sospoly) exits 130
with the one line ``tritools: interrupted`` -- before the fix it printed a 13-57-line traceback and
died by the signal.  An interrupt inside the interpreter's own ``site`` import (the first ~30 ms, more
on a loaded machine), before any tritools code runs, is outside tritools' reach and is skipped."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.cli_util import write
from tests.test_cli import example4_doc

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("delay", [0.2, 0.4, 0.7, 1.0])
def test_ctrl_c_during_start_up_exits_130_with_one_line(tmp_path, delay):
    problems = write(tmp_path, example4_doc())
    # the delay counts from the end of the interpreter's own start-up (its `site` import is outside tritools'
    # reach, and takes well over 0.1 s on a loaded machine): the child says "ready", then runs `python -m tritools`
    code = ("import sys; print('ready', flush=True); import runpy; sys.argv = ['tritools', 'solve', sys.argv[1]]; "
            "runpy.run_module('tritools', run_name='__main__', alter_sys=True)")
    proc = subprocess.Popen([sys.executable, "-c", code, str(problems)], cwd=tmp_path,
                            env=dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline() == "ready\n"
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    if proc.returncode == 0:            # a very fast machine finished first: nothing to interrupt
        pytest.skip("the command finished before the interrupt")
    if "init_import_site" in err:       # a loaded machine was still in the interpreter's own start-up
        pytest.skip("the interrupt came during Python's site import, before any tritools code runs")
    assert proc.returncode == 130 and err == "tritools: interrupted\n", (proc.returncode, err)


def test_a_library_import_keeps_python_s_handler():
    code = "import signal, tritools; print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)"
    # the child starts with SIGINT at its default: a parent that ignores it (a test worker) would hand SIG_IGN down,
    # and Python then keeps SIG_IGN (seen once in a README run of the full suite)
    out = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                         capture_output=True, text=True, timeout=60,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)).stdout
    assert out.strip() == "True"
