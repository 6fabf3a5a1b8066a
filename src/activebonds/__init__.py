"""activebonds: identify active particle-bond systems from motion capture.

Particles with masses; unary, binary and ternary springs; dampers; mechanical-neural bonds whose
neuron acts as a muscle (Stanciulescu & Louchet 2000). Parameters are identified from recorded
marker trajectories with the paper's self-adaptive evolution strategy.
"""

import os as _os

# XLA's CPU backend routes small reductions through YNNPACK fusions, which cost 2-3x more than
# its own loops on the tiny arrays of this problem (measured: benchmarks/profile.py). Opt out
# unless the user set the flag; it must be set before JAX creates its CPU backend.
_YNN = "xla_cpu_experimental_ynn_fusion_type"
if _YNN not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + f" --{_YNN}=").strip()

__version__ = "0.2.0"
