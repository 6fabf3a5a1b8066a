"""Programs compiled ahead, in a background thread, while the caller does other work.

A shooting stage needs its big programs (the normal equations by window, the damped step,
the shooting residuals, the one-step check) only after its warm start, whose own programs
compile and run first. XLA compiles a program on one core and releases Python's lock while it
does, so compiling the shooting's programs beside the warm start takes them off the stage's
critical path on a machine with two cores or more (``benchmarks/shooting.py``).

``ahead(jitted, *args)`` returns a callable that runs ``jitted``: by the program compiled in
the background for ``args``' shapes when it is ready, and by ``jitted`` itself for other
shapes, inside another transformation (tracers), or if the background compilation failed (the failure is then raised again by ``jitted``
where the caller can see it). The caller's precision (JAX's 64-bit mode, which a context can
set per thread) is the background's.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import jax
import jax.numpy as jnp

_POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix="activebonds-compile")


class Ahead:
    """``jitted``, called through the program compiled in the background where it fits."""

    def __init__(self, jitted, future: Future, signature):
        self.jitted, self._future, self._signature = jitted, future, signature
        self._compiled = None

    def __call__(self, *args):
        if self._future is not None:
            try:
                self._compiled = self._future.result()
            except Exception:  # noqa: BLE001 - the jitted call below says what is wrong
                self._compiled = None
            self._future = None
        traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(args))
        if self._compiled is not None and not traced and _signature(args) == self._signature:
            return self._compiled(*args)
        return self.jitted(*args)


def _signature(args):
    """The pytree structure and every leaf's shape, dtype and weak type: what a compiled
    program accepts."""
    leaves, tree = jax.tree.flatten(args)
    arrays = [x if hasattr(x, "shape") and hasattr(x, "dtype") else jnp.asarray(x) for x in leaves]
    return tree, tuple(
        (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False))) for x in arrays
    )


def ahead(jitted, *args) -> Ahead:
    """Start compiling ``jitted`` for ``args`` (arrays) in the background; the returned
    callable runs it."""
    x64 = jnp.zeros(()).dtype == jnp.float64

    def compile_():
        with jax.enable_x64(x64):
            return jitted.lower(*args).compile()

    return Ahead(jitted, _POOL.submit(compile_), _signature(args))
