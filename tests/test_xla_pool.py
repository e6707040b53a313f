"""JAX's CPU backend starts with one intra-op thread wherever idtool is imported
(idtool._xla_pool): jaxlib 0.10's batched LAPACK kernels deadlock a larger pool.

Each check runs in a fresh interpreter: the backend starts once per process."""

import os
import subprocess
import sys

import pytest

CPUS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
needs_cores = pytest.mark.skipif(CPUS < 2, reason="a pool of one thread is the default here")

# How many threads XLA's intra-op pool has, and whether each has the main thread's affinity
POOL = (
    "import os\n"
    "tasks = os.listdir('/proc/self/task')\n"
    "comm = {t: open(f'/proc/self/task/{t}/comm').read().strip() for t in tasks}\n"
    "pool = [int(t) for t in tasks if comm[t] == 'tf_XLAEigen']\n"
    "print(len(pool), all(os.sched_getaffinity(t) == os.sched_getaffinity(0) for t in pool))\n"
)
# Four independent batched LU solves in one program (241 12 x 12 matrices each: above
# the kernels' 2e5-FLOP threshold for splitting a batch), run 300 times: on 2 cores
# with a two-thread pool 4 to 5 runs of 6 never finished
DEADLOCK = (
    "import jax, jax.numpy as jnp, numpy as np\n"
    "rng = np.random.default_rng(0)\n"
    "a = [jnp.asarray(rng.standard_normal((241, 12, 12)) + 12 * np.eye(12)) for _ in range(4)]\n"
    "b = jnp.asarray(rng.standard_normal((241, 12, 1)))\n"
    "f = jax.jit(lambda *a: sum(jnp.linalg.solve(x, b).sum() + jnp.linalg.slogdet(x)[1].sum()"
    " for x in a))\n"
    "print(sum(float(f(*a)) for _ in range(300)) != 0.0)\n"
)


def run(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return done.stdout.strip()


@needs_cores
@pytest.mark.parametrize("order", ["import idtool, jax", "import jax, idtool"])
def test_the_backend_starts_with_one_pool_thread_whoever_imports_jax_first(order):
    code = f"{order}\nimport jax.numpy as jnp\nprint(jnp.zeros(2).dtype)\n{POOL}"
    dtype, pool = run(code).splitlines()
    # one pool thread, given the process's whole affinity back; 64-bit floats kept
    assert dtype == "float64" and pool == "1 True"


@needs_cores
def test_without_idtool_the_pool_has_a_thread_per_core():
    """The set-up the module changes (so the test above would fail without it)."""
    pool = run(f"import jax.numpy as jnp\njnp.zeros(2)\n{POOL}")
    assert pool == f"{CPUS} True"


@needs_cores
def test_concurrent_batched_lapack_calls_finish():
    """The deadlock's own program, after ``import idtool``: it finishes (a hang is a
    timeout, and the test fails)."""
    assert run(f"import idtool\n{DEADLOCK}") == "True"


def test_idtool_alone_still_does_not_import_jax():
    assert run("import sys, idtool\nprint('jax' in sys.modules)") == "False"


def test_a_backend_that_cannot_start_fails_at_first_use_not_at_import():
    """JAX_PLATFORMS naming a device without its plugin: ``import jax`` still works
    after ``import idtool`` (the error comes where JAX would raise it without idtool)."""
    env = dict(os.environ, JAX_PLATFORMS="cuda")
    done = subprocess.run(
        [sys.executable, "-c", "import idtool, jax\nprint('imported')"],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert done.returncode == 0 and done.stdout.strip() == "imported", done.stderr
