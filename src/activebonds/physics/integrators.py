"""The integrators a model is stepped with, by name, and the value a fit and a prediction carry:
an integrator with its substeps, which knows what it is (whether one step of it is the
recording's own backward difference, how its start velocity lags, its order).

Consumers ask the value (``Integrator(...).exact_backward``), never its name: a new scheme is
its step function in :data:`activebonds.physics.integrate.STEPS` and one :class:`Scheme` here.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..registry import Registry


@dataclass(frozen=True)
class Scheme:
    """What the rest of the package needs to know of an integration scheme."""

    name: str
    order: int  # of accuracy in the step: 1 (semi-implicit Euler), 2 (velocity Verlet)
    # one substep of it from (x_t, (x_t - x_t-1) / dt) lands on the recording's backward
    # difference: its start velocity is that difference itself, nothing to solve
    backward_exact: bool
    # at one substep, the start velocity is the backward difference plus half a kick of the
    # forces at frame t (velocity Verlet), rather than a solve
    half_kick_start: bool
    description: str

    def start_lag(self, substeps: int) -> float:
        """How far behind the backward difference a start velocity is under a constant
        acceleration a, in frames of a: Euler's N substeps start from v_b - dt (N+1)/(2N) a,
        Verlet's from v_b - dt/2 a."""
        return 0.5 * (substeps + 1) / substeps if self.order == 1 else 0.5


EULER = Scheme("euler", 1, True, False, "semi-implicit Euler")
VERLET = Scheme("verlet", 2, False, True, "velocity Verlet")
SCHEMES: Registry[Scheme] = Registry("integrator", (EULER, VERLET))
DEFAULT = EULER.name
names, scheme = SCHEMES.names, SCHEMES.find


@dataclass(frozen=True)
class Integrator:
    """A scheme with its substeps per frame."""

    method: str = DEFAULT
    substeps: int = 1

    @property
    def scheme(self) -> Scheme:
        return scheme(self.method)

    @property
    def exact_backward(self) -> bool:
        """Whether a prediction from a recorded state starts at the recording's backward
        difference itself (one substep of a scheme that is exact there): no start velocity
        to solve, and the one-step cost's optimum solved exactly where it is linear."""
        return self.substeps == 1 and self.scheme.backward_exact

    @property
    def half_kick_start(self) -> bool:
        """Whether the start velocity is the backward difference plus half a kick (one
        substep of velocity Verlet), with no solve."""
        return self.substeps == 1 and self.scheme.half_kick_start

    def start_lag(self) -> float:
        return self.scheme.start_lag(self.substeps)

    def describe(self) -> str:
        return f"{self.substeps} {self.method} substep(s)"
