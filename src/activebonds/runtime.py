"""Process-wide settings, applied by entry points (the command line, the benchmarks, the
tests), never by importing the package. The one exception is :func:`keep_compiled`, which
``fit`` and ``resume`` call so that a notebook's second fit of the same shapes starts without
compiling (it only turns on JAX's persistent cache where the process has none). An entry point
that handles Ctrl-C itself registers how to ask whether the user wants to stop
(:func:`on_stop_request`); the package's long loops poll it (:func:`stop_requested`).

XLA's CPU backend routes small reductions through YNNPACK fusions, which cost 2-3x more than
its own loops on the tiny arrays of this problem (measured: ``benchmarks/profile.py``).
:func:`fast_cpu_flags` opts out unless the user chose (``XLA_FLAGS`` already names the flag);
it must run before JAX's first computation, which creates the CPU backend. A Python user who
wants the same speed calls it first, or sets
``XLA_FLAGS=--xla_cpu_experimental_ynn_fusion_type=`` in the environment.
"""

from __future__ import annotations

import os

YNN_FLAG = "xla_cpu_experimental_ynn_fusion_type"
MIN_SECONDS_ENV = "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"


def fast_cpu_flags() -> None:
    """Add ``--xla_cpu_experimental_ynn_fusion_type=`` to ``XLA_FLAGS`` unless it is set."""
    flags = os.environ.get("XLA_FLAGS", "")
    if YNN_FLAG not in flags:
        os.environ["XLA_FLAGS"] = (flags + f" --{YNN_FLAG}=").strip()


def float64(fn):
    """Run ``fn`` with JAX's 64-bit mode on, scoped to the call (the process's setting is
    left as it was)."""
    import functools

    import jax

    @functools.wraps(fn)
    def scoped(*args, **kwargs):
        with jax.enable_x64(True):
            return fn(*args, **kwargs)

    return scoped


def compilation_cache() -> None:
    """Keep compiled programs between runs (a repeated fit of the same shapes starts at
    once): JAX's persistent cache in ``~/.cache/activebonds/jax``. ``ACTIVEBONDS_CACHE=off``
    disables it; ``ACTIVEBONDS_CACHE=DIR`` moves it. (The command line's choice, for the
    processes that run its work elsewhere, e.g. a sweep's Ray workers.)"""
    from pathlib import Path

    where = os.environ.get("ACTIVEBONDS_CACHE", "")
    if where.lower() in ("off", "0", "no"):
        return
    folder = Path(where or Path.home() / ".cache" / "activebonds" / "jax")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    import jax

    jax.config.update("jax_compilation_cache_dir", str(folder))
    if MIN_SECONDS_ENV not in os.environ:  # keep every program: a fit's small ones add up
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def keep_compiled() -> None:
    """:func:`compilation_cache` unless the process already keeps compiled programs somewhere
    (JAX's ``jax_compilation_cache_dir`` set) or ``ACTIVEBONDS_CACHE=off``: called by the
    Python API's ``fit`` and ``resume``, so that a second fit of the same model and window in a
    notebook loads the first one's programs instead of compiling them again (each fit builds
    new closures over its data, which JAX's in-memory cache does not recognise)."""
    import jax

    if jax.config.jax_compilation_cache_dir is None:
        compilation_cache()


_stop_check = None  # the entry point's "has the user asked to stop?" (the command line's Ctrl-C)


def on_stop_request(check) -> None:
    """Register ``check() -> bool``: whether the user has asked the process to stop (the
    command line's Ctrl-C, :mod:`activebonds.cli.interrupts`). Long loops without a chunked
    safe point poll it between their steps (:func:`stop_requested`: the refinement's
    Levenberg-Marquardt) and end there, saving what they have. None unregisters."""
    global _stop_check
    _stop_check = check


def stop_requested() -> bool:
    """Whether the registered check says the user asked to stop (False without one)."""
    return _stop_check is not None and bool(_stop_check())
