"""Physics of particle-bond systems: forces (the bond kinds' own, summed) and time integration."""

from .forces import bond_forces, neuron_activity, total_force, uniform_field
from .integrate import (
    advance,
    euler_step,
    rollout,
    rollout_states,
    start_velocity,
    verlet_step,
)

__all__ = [
    "advance",
    "bond_forces",
    "euler_step",
    "neuron_activity",
    "rollout",
    "rollout_states",
    "start_velocity",
    "total_force",
    "uniform_field",
    "verlet_step",
]
