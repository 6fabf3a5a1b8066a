"""The genome layout: which numbers are free, their bounds, and their bond-type groups.

DESIGN.md §3: genes (:class:`~activebonds.model.genes.Gene`) are grouped by bond type (all occurrences of a type share one parameter
set); every gene has bounds; positive quantities with wide bounds are searched in log space.
``decode`` maps a genome (search space) to :class:`Params` with one gather per leaf, so it
vmaps over a population at no cost; then (:meth:`Layout.derive`) a free gravity magnitude
becomes the vector ``magnitude * direction``, and with ``total_mass`` the free masses'
genes (positive weights w_i, log-scaled) become ``m_i = (total - fixed) * w_i / sum(w)``, so
the total holds exactly whatever the genes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .genes import Gene
from .params import Params


# Bounds of a free mass given without min/max, from the file value v (bond parameters declare
# theirs: activebonds.bonds).
def mass_bounds(v: float) -> tuple[float, float]:
    return (v / 10, v * 10)


# Bounds of a free gravity magnitude given without min/max, from the file value g.
def gravity_bounds(g: float) -> tuple[float, float]:
    return (g / 2, g * 2) if g > 0 else (g - 10.0, g + 10.0)


@dataclass(frozen=True, eq=False)
class Layout:
    """Free parameters of a model as a flat genome, and how to put them back."""

    genes: tuple[Gene, ...]
    groups: tuple[str, ...]  # name of each group (bond type or particle mass)
    group_slots: np.ndarray  # [n_groups, S] particles at the extremities of each occurrence, -1 pad
    base: Params  # fixed values (and file values of free ones)
    index: Params  # same shapes, int: gene index or -1 for fixed entries
    # a free gravity magnitude: every axis of index.gravity is its gene, times this unit vector
    gravity_direction: np.ndarray | None = None
    # total_mass less the fixed masses: the free masses' genes are weights of this remainder
    mass_rest: float | None = None

    @property
    def n_genes(self) -> int:
        return len(self.genes)

    @property
    def lower(self) -> np.ndarray:
        return np.array([_to_search(g.lower, g.log) for g in self.genes], dtype=np.float64)

    @property
    def upper(self) -> np.ndarray:
        return np.array([_to_search(g.upper, g.log) for g in self.genes], dtype=np.float64)

    @property
    def log(self) -> np.ndarray:
        return np.array([g.log for g in self.genes], dtype=bool)

    @property
    def gene_group(self) -> np.ndarray:
        return np.array([g.group for g in self.genes], dtype=np.int32)

    def initial(self) -> np.ndarray:
        """The model file's values in search space."""
        return np.array([_to_search(g.value, g.log) for g in self.genes], dtype=np.float64)

    def natural(self, genome: np.ndarray) -> np.ndarray:
        out = np.array(genome, dtype=np.float64)
        out[..., self.log] = np.exp(out[..., self.log])  # only the log genes (no overflow)
        return out

    def decode(self, genome):
        """Genome (search space, [G]) -> Params. Pure JAX; vmap it over a population."""
        # exp of the log-scaled genes only (few of a neural model's), put back by one gather
        log = np.flatnonzero(np.asarray(self.log, bool))
        if len(log) == len(self.genes):
            values = jnp.exp(genome)
        elif len(log):
            where = np.arange(len(self.genes))
            where[log] = len(self.genes) + np.arange(len(log))
            values = jnp.concatenate([genome, jnp.exp(genome[log])])[where]
        else:
            values = genome
        padded = jnp.concatenate([values, jnp.zeros((1,), values.dtype)])

        def leaf(base, index):
            index = np.asarray(index)
            if index.size == 0 or (index < 0).all():
                return jnp.asarray(base, values.dtype)
            gathered = padded[np.where(index >= 0, index, len(self.genes))]
            # the free entries' values are the genome's: 0 in the program's constant, so that
            # models of other values and the same structure share their programs
            fixed = np.where(index >= 0, 0.0, np.asarray(base, np.float64))
            return jnp.where(index >= 0, gathered, jnp.asarray(fixed, values.dtype))

        return self.derive(jax.tree_util.tree_map(leaf, self.base, self.index), jnp)

    def derive(self, params: Params, xp=np) -> Params:
        """Params whose gathered genes are turned into the model's numbers: the gravity vector
        from its magnitude, the free masses from their weights (``xp``: numpy or jax.numpy).
        The identity for a model with neither."""
        if self.gravity_direction is not None:
            params = params._replace(gravity=params.gravity * self.gravity_direction)
        if self.mass_rest is not None:
            free = np.asarray(self.index.mass) >= 0
            w = params.mass
            total = xp.sum(xp.where(free, w, 0.0))
            params = params._replace(mass=xp.where(free, self.mass_rest * (w / total), w))
        return params


def _to_search(x: float, log: bool) -> float:
    return math.log(x) if log else x


def pick_log(lower: float, upper: float, log: bool | None) -> bool:
    if log is not None:
        return log
    return lower > 0 and upper / lower >= 100
