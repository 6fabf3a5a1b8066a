"""A registry: named things in the order they were registered, found by name. The bond kinds
(:mod:`.bonds.registry`), the post-fit stages (:mod:`.identify.stages`), the costs
(:mod:`.identify.costs`) and the integration schemes (:mod:`.physics.integrators`) are each
one; a new entry is one line where the registry is made, or :meth:`Registry.register`
(:meth:`Registry.registered` for a ``with`` block) from outside."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Generic, Protocol, TypeVar


class Named(Protocol):
    name: str


T = TypeVar("T", bound=Named)


class Registry(Generic[T]):
    """``what`` (e.g. "bond kind") by name, in order."""

    def __init__(self, what: str, entries: Iterable[T] = ()):
        self.what = what
        self._entries: dict[str, T] = {}
        for entry in entries:
            self.register(entry)

    def register(self, entry: T) -> T:
        """Add ``entry`` after the ones registered before it; a name taken is refused."""
        if entry.name in self._entries:
            raise ValueError(f"{self.what} '{entry.name}' is already registered")
        self._entries[entry.name] = entry
        return entry

    def unregister(self, name: str) -> None:
        del self._entries[name]

    @contextmanager
    def registered(self, entry: T) -> Iterator[T]:
        """``entry`` registered inside the ``with`` block only."""
        self.register(entry)
        try:
            yield entry
        finally:
            self.unregister(entry.name)

    def get(self, name: str) -> T:
        """The entry ``name`` (KeyError where there is none)."""
        return self._entries[name]

    def find(self, name: str) -> T:
        """The entry ``name``, or a ValueError naming the known ones: "unknown cost 'x';
        choose one of a, b"."""
        try:
            return self._entries[name]
        except KeyError:
            known = ", ".join(self._entries)
            raise ValueError(f"unknown {self.what} {name!r}; choose one of {known}") from None

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def entries(self) -> tuple[T, ...]:
        return tuple(self._entries.values())
