"""The tests run OpenBLAS on one thread per process (tests/conftest.py): with its own
threads, two xdist workers on two cores spent a quarter of some files' CPU waiting."""

import os
from pathlib import Path

import numpy as np
import scipy.linalg
from openblas_helpers import openblas_threads


def test_openblas_runs_one_thread_in_the_test_processes():
    # load both libraries, as the fits do
    np.linalg.solve(np.eye(3), np.ones(3))
    scipy.linalg.solve_triangular(np.eye(3), np.ones(3))
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    if not Path("/proc/self/maps").exists():
        return  # no /proc to find the libraries in: the variable above is what counts
    threads = openblas_threads()
    assert threads, "no OpenBLAS found among the loaded libraries"
    assert set(threads.values()) == {1}, threads
