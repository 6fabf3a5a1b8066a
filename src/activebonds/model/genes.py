"""A gene: one free number of a model, known by what it belongs to, not by a string.

A gene's identity is a set of fields (:class:`Gene`): its ``owner`` (a particle's mass, the
gravity magnitude, a bond parameter or a bond kind's shared, model-level parameter), the
bond kind and the model-file bonds it sets, its file ``key``, and for the parameters with
several numbers per bond the axis (vectors) or the weights' part and input bond. Its
``name`` is derived from these fields: a machine key stored in checkpoints, histories,
``uncertainty.json`` and sweep summaries, unchanged since the first model files::

    mass:Head.mass                 owner "mass", particle "Head", key "mass"
    mass:Head.weight               the same under total_mass (a weight of the free mass)
    gravity.magnitude              owner "gravity", key "magnitude"
    drive.frequency                owner "shared", kind "binary", key "drive.frequency"
    bond[0].stiffness              owner "bond", kind "binary", bonds (0,), key "stiffness"
    bond[3].anchor[2]              ... key "anchor", axis 2
    bond[2].weights.length[1]      ... key "weights", part "length", source 1
    type:neck.damping              ... type "neck", bonds (every bond of the type it sets)

Bond genes of a ``type`` are shared by every bond of that type (one gene per key), so they are
named by the type; the others by their bond's index in the model file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

Owner = Literal["mass", "gravity", "bond", "shared"]


@dataclass(frozen=True)
class Gene:
    """One free number of a model: its identity (fields), bounds and file value."""

    owner: Owner
    key: str  # the file key: "stiffness", "anchor", "weights", "drive.frequency", "mass", ...
    kind: str | None = None  # the bond kind of a bond or shared gene
    bonds: tuple[int, ...] = ()  # model-file indices of the bonds it sets (in file order)
    type: str | None = None  # a bond gene's type (shared by every bond of the type)
    particle: str | None = None  # a mass gene's particle
    field: str | None = None  # its array in ``params.bonds[kind]`` (bond and shared genes)
    part: str | None = None  # a weights gene's part: "length" or "rate"
    axis: int | None = None  # a vector gene's axis
    source: int | None = None  # a weights gene's input bond: its position among the kind's bonds
    group: int = 0  # bond-type group (crossover unit), index into ``Layout.groups``
    lower: float = -math.inf  # search bounds, natural units
    upper: float = math.inf
    log: bool = False  # searched in log space
    value: float = 0.0  # the model file's value (natural units)

    @property
    def group_name(self) -> str:
        """The name of its group: ``mass:Head``, ``gravity``, ``drive``, ``type:neck``,
        ``bond[2]``."""
        if self.owner == "mass":
            return f"mass:{self.particle}"
        if self.owner == "gravity":
            return "gravity"
        if self.owner == "shared":
            return self.key.split(".", 1)[0]  # the top-level table of the model file
        return bond_group(self.bonds[0], self.type)

    @property
    def suffix(self) -> str:
        """Its name within its group: ``stiffness``, ``anchor[2]``, ``weights.length[1]``."""
        if self.owner == "shared":
            return self.key.split(".", 1)[1]
        if self.part is not None:
            return f"{self.key}.{self.part}[{self.source}]"
        if self.axis is not None:
            return f"{self.key}[{self.axis}]"
        return self.key

    @property
    def name(self) -> str:
        """The machine key (``bond[0].stiffness``): derived, never parsed back."""
        return f"{self.group_name}.{self.suffix}"


def bond_group(index: int, type: str | None) -> str:
    """The group of the bond ``index`` of the model file: its type's, else its own."""
    return f"type:{type}" if type else f"bond[{index}]"
