"""Static topology apart from dynamic numbers (brax/MJX style).

``Topology`` holds index arrays (which particles each bond joins); ``Params`` holds the numbers
of one individual, as array leaves that can be vmapped over a population.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


@dataclass(frozen=True, eq=False)
class Topology:
    """Particle count, dimension and bond index arrays: fixed for a whole identification."""

    n_particles: int
    dimension: int
    unary: np.ndarray  # [U] particle index of each unary bond
    binary: np.ndarray  # [B, 2] particle indices (i, j) of each binary bond
    neural: np.ndarray  # [B] bool: binary bond b carries a neuron
    ternary: np.ndarray  # [T, 3] particle indices (i, j, k); the angle is at j

    @property
    def n_binary(self) -> int:
        return int(self.binary.shape[0])


class Params(NamedTuple):
    """The numbers of one model (SI units). Shapes: P particles, D axes, U/B/T bonds."""

    mass: np.ndarray  # [P]
    gravity: np.ndarray  # [D]
    unary_k: np.ndarray  # [U]
    unary_c: np.ndarray  # [U]
    unary_anchor: np.ndarray  # [U, D]
    k: np.ndarray  # [B] stiffness
    l0: np.ndarray  # [B] rest length
    c: np.ndarray  # [B] damping
    gain: np.ndarray  # [B] muscle gain (N); used where neural
    threshold: np.ndarray  # [B]
    w_len: np.ndarray  # [B, B] weight of bond j's elongation in neuron b (diagonal unused)
    w_rate: np.ndarray  # [B, B] weight of bond j's elongation rate in neuron b
    tern_k: np.ndarray  # [T] flexion stiffness
    tern_angle: np.ndarray  # [T] rest angle (radians)
