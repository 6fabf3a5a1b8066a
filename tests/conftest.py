"""Shared test setup (the test process is an entry point): the command line's XLA flags, and
every test runs JAX in float64."""

import jax

from activebonds.runtime import fast_cpu_flags

fast_cpu_flags()
jax.config.update("jax_enable_x64", True)
