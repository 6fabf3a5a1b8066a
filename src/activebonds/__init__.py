"""activebonds: identify active particle-bond systems from motion capture.

Particles with masses; unary, binary and ternary springs; dampers; mechanical-neural bonds whose
neuron acts as a muscle (Stanciulescu & Louchet 2000). Parameters are identified from recorded
marker trajectories with the paper's self-adaptive evolution strategy.

Importing it changes nothing in the process (``XLA_FLAGS``, JAX's x64 mode, matplotlib's
backend stay as they were): entry points make such choices (:mod:`activebonds.runtime`).
"""

__version__ = "0.2.0"
