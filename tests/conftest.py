"""Shared test setup: every test runs JAX in float64."""

import jax

jax.config.update("jax_enable_x64", True)
