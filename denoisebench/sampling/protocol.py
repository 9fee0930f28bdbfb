"""The Sampler protocol (docs/architecture.md, Sampler protocol), the budget, and the errors a sampler is told.

A sampler is any object with::

    name: str
    def sample(self, budget: Budget, rounds: RoundHandle) -> None: ...

``sample`` spends ``budget`` by calling ``rounds.render(counts)`` as often as it likes, each call
with an H×W map of *additional* samples per pixel (non-negative integers), and reading what comes
back: the accumulated per-pixel means and variances of the mean (``"color"``, ``"color_var"``, ...),
the samples per pixel so far and the round's render seconds (a ``RoundBuffers``). It returns when it
is done; the harness (:func:`~denoisebench.sampling.harness.run_sampler`) then keeps the buffers and
the spp map. Only ``sample`` is required of a plugin; ``name`` defaults to the spec it was loaded by.

Notes
-----
* **The harness enforces the budget.** A round asking for more than is left is cut down to what is
  left (proportionally, never above any pixel's request) and :attr:`RoundHandle.cut` says so; the
  next ``render`` raises :class:`BudgetExhausted`, which the harness catches when it escapes
  ``sample``. A sampler cannot spend more than its budget, only less.
* Seconds budgets count the sampler's own decision time (the wall time between rounds) beside the
  render seconds. Rounds are cut to the samples that fit the remaining time at the rate measured in
  this frame's earlier rounds; the first round of a seconds budget is capped at one sample per pixel,
  the probe that measures the rate.
* A pixel with no sample has a mean of 0, a biased value: the result counts such pixels
  (:attr:`~denoisebench.sampling.harness.SamplerResult.pixels_without_samples`) and the report says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from denoisebench.errors import UserInputError


class BudgetExhausted(Exception):
    """Raised by ``RoundHandle.render`` once the budget is spent (the harness catches it)."""


class SamplerRequestError(ValueError):
    """A round request the harness refuses (wrong shape, negative, NaN, not integral, or empty)."""


@dataclass(frozen=True)
class Budget:
    """A frame's budget: ``spp`` (mean samples per pixel over the frame) or ``seconds``, exactly one.

    ``total_samples(pixels)`` is ``round(spp * pixels)``: the samples a sampler may request in all.
    """

    spp: float | None = None
    seconds: float | None = None

    def __post_init__(self) -> None:
        if (self.spp is None) == (self.seconds is None):
            raise UserInputError("a sampler budget is a mean spp or a number of seconds (exactly one)")
        value = self.spp if self.spp is not None else self.seconds
        if not value > 0 or value != value or value == float("inf"):
            raise UserInputError(f"a sampler budget must be a positive finite number (got {value})")

    def total_samples(self, pixels: int) -> int | None:
        """Samples this budget allows over ``pixels`` pixels (None for a seconds budget)."""
        return None if self.spp is None else int(round(self.spp * pixels))

    def label(self) -> str:
        return f"{self.spp:g} spp" if self.spp is not None else f"{self.seconds:g} s"


@runtime_checkable
class Sampler(Protocol):
    name: str

    def sample(self, budget: Budget, rounds) -> None: ...


def sampler_name(sampler: object, fallback: str = "unnamed") -> str:
    """``sampler.name`` or ``fallback``; TypeError (one line) when ``sample`` is not callable or the name is no string."""
    if not callable(getattr(sampler, "sample", None)):
        raise TypeError(f"{type(sampler).__name__} object has no callable sample(budget, rounds)")
    name = getattr(sampler, "name", None) or fallback
    if not isinstance(name, str):
        raise TypeError(f"sampler name must be a string, got {type(name).__name__}")
    return name
