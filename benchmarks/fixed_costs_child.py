"""One command of the command line, run in this process with JAX's compile events recorded.

    python -P benchmarks/fixed_costs_child.py OUT.json activebonds-ARGS...

Writes OUT.json: the wall seconds from start (interpreter start-up excluded) to the end of the
command, its exit code, and every compilation JAX reports (``jax.monitoring``: tracing,
lowering to MLIR, XLA's backend compile, each with the jitted function's name and the second
it ended), with the persistent cache's hits and misses. Used by ``fixed_costs.py``.
"""

from __future__ import annotations

import json
import os
import sys
import time

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.getcwd()) != _HERE]

START = time.perf_counter()


def main() -> None:
    out, argv = sys.argv[1], sys.argv[2:]
    from jax import monitoring

    events: list[dict] = []
    counts: dict[str, int] = {}

    def on_duration(event, duration, **kw):
        if event.startswith("/jax/core/compile/"):
            events.append(
                {
                    "event": event.rsplit("/", 1)[1].removesuffix("_duration"),
                    "seconds": float(duration),
                    "at": time.perf_counter() - START,
                    "fun": str(kw.get("fun_name", "")),
                }
            )

    def on_event(event, **_):
        if event.startswith("/jax/compilation_cache/"):
            key = event.rsplit("/", 1)[1]
            counts[key] = counts.get(key, 0) + 1
            if key in ("cache_misses", "cache_hits"):
                events.append({"event": key, "seconds": 0.0, "at": time.perf_counter() - START})

    monitoring.register_event_duration_secs_listener(on_duration)
    monitoring.register_event_listener(on_event)
    sys.argv = ["activebonds", *argv]
    from activebonds.cli.main import main as cli_main

    code = 0
    try:
        cli_main()
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    wall = time.perf_counter() - START
    with open(out, "w") as f:
        json.dump({"wall": wall, "code": code, "events": events, "cache": counts}, f)


if __name__ == "__main__":
    main()
