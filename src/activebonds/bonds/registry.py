"""The registered bond kinds, in order: name -> :class:`~activebonds.bonds.kind.BondKind`.

The order is the order in which kinds' forces are summed and their topology is listed.
"""

from __future__ import annotations

from ..registry import Registry
from .kind import BondKind

KINDS: Registry[BondKind] = Registry("bond kind")
register, unregister, registered = KINDS.register, KINDS.unregister, KINDS.registered
get, names, kinds = KINDS.get, KINDS.names, KINDS.entries


def listing(words: list[str] | tuple[str, ...], last: str = "or") -> str:
    """ "'a', 'b' or 'c'" (the kinds in messages)."""
    quoted = [f"'{w}'" for w in words]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} {last} {quoted[-1]}"


def drive_kinds() -> tuple[str, ...]:
    """The registered kinds whose bonds read the rhythmic drive (they hold its shared
    ``drive_frequency``: the neurons' drive, the periodic forces), in order."""
    return tuple(k.name for k in kinds() if "drive_frequency" in k.fields)


def drive_kind() -> str | None:
    """The first registered kind that reads the rhythmic drive, or None."""
    return next(iter(drive_kinds()), None)
