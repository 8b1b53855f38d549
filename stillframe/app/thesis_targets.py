"""The thesis's reduction targets that ``reproduce`` checks and ``montecarlo`` counts."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Target:
    """A reduction every listed floor must reach."""

    scene: str
    quantity: str
    floors: tuple[int, ...]
    minimum_pct: float

    def describe(self) -> str:
        """The target in words, as the report prints it (``scene: quantity reduction >= N % on
        ...``)."""
        where = ("every floor" if len(self.floors) == 3
                 else ", ".join(f"floor {f}" for f in self.floors))
        return f"{self.scene}: {self.quantity} reduction >= {self.minimum_pct:g} % on {where}"

    def met(self, reduction_pct: dict[str, list[float]]) -> bool:
        """Whether every floor of the target reached ``minimum_pct`` in ``reduction_pct`` (per
        quantity, the reductions of floors 1-3 in %)."""
        return all(reduction_pct[self.quantity][f - 1] >= self.minimum_pct for f in self.floors)


TARGETS: tuple[Target, ...] = (
    Target("thesis_lqg", "displacement", (1, 2, 3), 50.0),
    Target("thesis_lqg", "velocity", (1, 2, 3), 50.0),
    Target("thesis_euk_ekf", "displacement", (3,), 85.0),
    Target("lqg_mismatch", "displacement", (1, 2, 3), 50.0),
    Target("lqg_mismatch", "velocity", (1, 2, 3), 50.0),
)
