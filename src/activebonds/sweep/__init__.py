"""Many fits from one manifest, run in parallel on Ray (an optional extra) or one after another.

:func:`load_manifest` expands and checks a manifest (every problem found before anything
runs), :func:`run_ray` / :func:`run_sequential` bring each fit's run directory to its end
(skipping finished runs, resuming interrupted ones), :func:`write_summary` tabulates them.
The ``sweep`` command is these in order; docs/SWEEP.md describes the manifest.
"""

from .manifest import Job, load_manifest
from .outcome import Outcome
from .run import check_out, ray_available, run_job, run_ray, run_sequential, start_ray
from .summary import write_summary

__all__ = [
    "Job",
    "Outcome",
    "check_out",
    "load_manifest",
    "ray_available",
    "run_job",
    "run_ray",
    "run_sequential",
    "start_ray",
    "write_summary",
]
