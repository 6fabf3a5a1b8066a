"""activebonds: identify active particle-bond systems from motion capture.

Particles with masses; unary, binary and ternary springs; dampers; mechanical-neural bonds whose
neuron acts as a muscle (Stanciulescu & Louchet 2000). Parameters are identified from recorded
marker trajectories with the paper's self-adaptive evolution strategy.

Importing it changes nothing in the process (``XLA_FLAGS``, JAX's x64 mode, matplotlib's
backend stay as they were): entry points make such choices (:mod:`activebonds.runtime`).
"""

from .lazy import exports

__version__ = "0.3.0"

# The public face, imported on first use (importing the package stays light): everything else
# lives in its subpackage (model, physics, data, identify, report, experiments, cli).
_PUBLIC = {
    "fit": "activebonds.identify.driver",
    "resume": "activebonds.identify.driver",
    "FitResult": "activebonds.identify.driver",
    "FitSettings": "activebonds.identify.settings",
    "FillSettings": "activebonds.identify.gaps.settings",
    "fill_file": "activebonds.identify.gaps.files",
    "FilledFile": "activebonds.identify.gaps.files",
    "load_model": "activebonds.model.io",
    "save_model": "activebonds.model.io",
    "read_trajectory": "activebonds.data.readers",
    "write_trajectory": "activebonds.data.writers",
    "simulate": "activebonds.simulation",
    "write_report": "activebonds.report.html",
}

__all__ = sorted(_PUBLIC)


__getattr__, __dir__ = exports(__name__, _PUBLIC)
