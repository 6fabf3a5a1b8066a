"""Shared test setup (the test process is an entry point): the command line's XLA flags, every
test runs JAX in float64, and one compilation cache for the whole run.

The cache: the first process (pytest's controller) makes a fresh folder and names it in
``ACTIVEBONDS_CACHE``, which the xdist workers and every command line a test starts inherit, so
a program one test compiled is loaded, not compiled again, by the next (the results are the
same: a cached program is the same program). It is removed at the end of the run; the user's
``~/.cache/activebonds`` is never used. ``ACTIVEBONDS_CACHE=off pytest`` runs without it.
"""

import os
import shutil
import tempfile

# every program is kept (JAX's default keeps those that took 1 s to compile), as the command
# line and ``fit`` do; set before JAX is imported, so the command lines the tests start read it
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
# one BLAS thread per process: the workers (one per core) already fill the cores, and the
# small LAPACK calls the tests make (the fill's 18 x 18 blocks) took 10 times longer with
# OpenBLAS's threads waking on a busy machine; the xdist workers and the command lines the
# tests start inherit it (read when NumPy loads OpenBLAS)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

from activebonds.runtime import compilation_cache, fast_cpu_flags  # noqa: E402

_OWNER = "ACTIVEBONDS_TEST_CACHE_OWNER"
if "ACTIVEBONDS_CACHE" not in os.environ:
    os.environ["ACTIVEBONDS_CACHE"] = tempfile.mkdtemp(prefix="activebonds-test-jax-")
    os.environ[_OWNER] = str(os.getpid())

fast_cpu_flags()
jax.config.update("jax_enable_x64", True)
compilation_cache()


def pytest_unconfigure(config):
    if os.environ.get(_OWNER) == str(os.getpid()):
        shutil.rmtree(os.environ["ACTIVEBONDS_CACHE"], ignore_errors=True)
