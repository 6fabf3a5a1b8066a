"""The registered bond kinds, in order: name -> :class:`~activebonds.bonds.kind.BondKind`.

The order is the order in which kinds' forces are summed and their topology is listed.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from .kind import BondKind

_KINDS: dict[str, BondKind] = {}


def register(kind: BondKind) -> BondKind:
    """Add a kind (after the ones registered before it)."""
    if kind.name in _KINDS:
        raise ValueError(f"bond kind '{kind.name}' is already registered")
    _KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    del _KINDS[name]


@contextmanager
def registered(kind: BondKind) -> Iterator[BondKind]:
    """The kind registered inside the ``with`` block only."""
    register(kind)
    try:
        yield kind
    finally:
        unregister(kind.name)


def get(name: str) -> BondKind:
    return _KINDS[name]


def names() -> tuple[str, ...]:
    return tuple(_KINDS)


def kinds() -> tuple[BondKind, ...]:
    return tuple(_KINDS.values())


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
