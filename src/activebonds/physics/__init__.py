"""Physics of particle-bond systems: forces per bond family and time integration."""

from .forces import FAMILIES, neuron_activity, total_force
from .integrate import (
    advance,
    euler_step,
    rollout,
    rollout_states,
    start_velocity,
    verlet_step,
)

__all__ = [
    "FAMILIES",
    "advance",
    "euler_step",
    "neuron_activity",
    "rollout",
    "rollout_states",
    "start_velocity",
    "total_force",
    "verlet_step",
]
