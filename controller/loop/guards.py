"""Force guards as data, and the pure function that evaluates them on a wrench reading.

A guard says: when this quantity crosses this limit, take this action. Example (the default
grasp guards): ``Guard("force_n", ">", 12.0, "retreat", "excessive force")``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from drivers.interfaces import Wrench

Quantity = Literal["fx_n", "fy_n", "fz_n", "tx_nm", "ty_nm", "tz_nm", "force_n"]
Action = Literal["stop", "retreat"]


@dataclass(frozen=True)
class Guard:
    """``quantity op limit`` triggers ``action``.

    quantity: a wrench component or ``force_n`` (magnitude of the force vector);
    op: ``>`` / ``<`` compare the signed value, ``abs>`` its magnitude;
    limit: the value compared with (N for forces, N*m for torques);
    action: ``stop`` (end the motion where it is) or ``retreat`` (end it and back off);
    name: what the guard protects against, used in reports.
    """

    quantity: Quantity
    op: Literal[">", "<", "abs>"]
    limit: float
    action: Action
    name: str = field(default="")


def value_of(wrench: Wrench, quantity: Quantity) -> float:
    """The reading's ``quantity`` (N or N*m; ``force_n``: the force vector's magnitude)."""
    return wrench.force_n if quantity == "force_n" else getattr(wrench, quantity)


def tripped(guard: Guard, wrench: Wrench) -> bool:
    """Whether ``wrench`` trips ``guard`` (strictly beyond its limit)."""
    v = value_of(wrench, guard.quantity)
    if guard.op == ">":
        return v > guard.limit
    if guard.op == "<":
        return v < guard.limit
    return abs(v) > guard.limit


def first_tripped(wrench: Wrench, guards: tuple[Guard, ...] | list[Guard]) -> Guard | None:
    """The first guard (in order) that the reading trips, or None."""
    for guard in guards:
        if tripped(guard, wrench):
            return guard
    return None
