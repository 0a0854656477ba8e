"""The low level's settings: the sampling ball, its budget and rounds, the seed, screening."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from twolevel.models.rollout import Backend

if TYPE_CHECKING:
    from twolevel.world.world import Settings

__all__ = ["LowLevelSettings"]


@dataclass(frozen=True)
class LowLevelSettings:
    """Everything the low level is configured by (one docstring per field)."""

    r: float = 0.3
    """Radius of the sampling ball in (δ/δ_max, γ) [-] (the paper's r)."""
    samples: int = 200
    """The sampling budget [candidates per step]."""
    rounds: tuple[int, ...] = (32, 64)
    """Candidates per round; the rest of the budget goes in one last round."""
    seed: int = 0
    """The run's seed (sampling is seeded per step from it)."""
    delta_max: float = 0.5
    """Steering limit [rad]."""
    backend: Backend = "auto"
    """Rollout backend (:mod:`twolevel.models.rollout`)."""
    least_violation: bool = True
    """When nothing satisfies, do not brake if braking violates the rules worse than u* or a
    sampled candidate (:mod:`twolevel.control.low_level.brake`); False is the paper's plain rule."""
    safety: bool = True
    """Verify every control before it runs, else run the fail-safe verified earlier
    (:mod:`twolevel.control.low_level.guard`); False is the paper's low level alone."""
    safety_rounds: int = 1
    """With the safety layer on, rounds of sampling at most (the rest of the budget is spent only
    without it; :mod:`twolevel.control.low_level.sampling`)."""
    screen: tuple[int, ...] = (3,)
    """The cuts j [steps] of the prediction on whose prefixes candidates are screened, in turn,
    before their full rollout (empty: off; :mod:`twolevel.control.low_level.screening`; it never
    changes the decision)."""

    @classmethod
    def of(cls, settings: "Settings", **kw: Any) -> "LowLevelSettings":
        """A scenario's settings (its controller section's r, samples, and the run's seed), with
        the fields ``kw`` given."""
        return cls(r=settings.r, samples=settings.samples, seed=settings.seed, **kw)

    def round_sizes(self) -> list[int]:
        """Candidates per round, summing to ``samples``."""
        out: list[int] = []
        left = self.samples
        i = 0
        while left > 0:
            k = min(self.rounds[min(i, len(self.rounds) - 1)] if self.rounds else left, left)
            if i >= len(self.rounds):
                k = left  # the rest in one batch
            out.append(k)
            left -= k
            i += 1
        return out
