"""What one fit of a sweep did, as the runners report it and the summary tabulates it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Outcome:
    """What one fit did in this sweep and where its run stands."""

    name: str
    action: str  # ran, resumed, skipped or error
    status: str  # the run's status (completed, failed, ...), or error, lost
    message: str = ""  # why, for an error
    row: dict = field(default_factory=dict)  # the summary's numbers (summary.row)

    @property
    def ok(self) -> bool:
        return self.status == "completed"


Done = Callable[[Outcome], None]  # hears of each fit as it ends
