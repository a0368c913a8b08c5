"""What the runner asks of a policy: :class:`BatchPolicy`, with its defaults in
:class:`PolicyBase`, and :func:`as_batch_policy` for any object that only has ``act_batch``."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["BatchPolicy", "PolicyBase", "as_batch_policy"]


@runtime_checkable
class BatchPolicy(Protocol):
    """A policy of :func:`~uav_formation_env.evaluation.run_episodes`.

    Attributes:
        needs_neighbour_index: called as ``act_batch(obs, neighbour_index)`` with the local
            layout's (B, N, S) slot index (whose plans each UAV receives).
        accepts_tensors: takes torch observations as they are (else numpy copies).
        plans: (B, N, H, 3) the plans broadcast at the last step [m/s^2], or None.
    """

    needs_neighbour_index: bool
    accepts_tensors: bool
    plans: np.ndarray | None

    def act_batch(self, obs: Any, *neighbour_index: Any) -> Any:
        """(B, N, dim) observations -> (B, N, 3) normalised actions in [-1, 1]."""

    def reset(self, batch_size: int = 1, seeds: Sequence[int | None] | None = None) -> None:
        """Before an episode batch: one random stream per episode seed, if stateful."""

    def records(self) -> Any | None:
        """Per-step records (``triggered``, ``j_pre``, ``j_exec``, (T, B, N)) or None."""


class PolicyBase:
    """The defaults of :class:`BatchPolicy`: stateless, numpy in, no plans, no records."""

    needs_neighbour_index = False
    accepts_tensors = False
    plans: np.ndarray | None = None

    def reset(self, batch_size: int = 1, seeds: Sequence[int | None] | None = None) -> None:
        """Nothing to reset."""

    def records(self) -> Any | None:
        """No records."""
        return None


class _Defaults(PolicyBase):
    """An object with ``act_batch`` (and any of the other members) as a :class:`BatchPolicy`."""

    def __init__(self, policy: Any) -> None:
        self.policy = policy
        self.needs_neighbour_index = bool(getattr(policy, "needs_neighbour_index", False))
        self.accepts_tensors = bool(getattr(policy, "accepts_tensors", False))

    @property
    def plans(self) -> np.ndarray | None:  # type: ignore[override]
        return getattr(self.policy, "plans", None)

    def act_batch(self, obs: Any, *neighbour_index: Any) -> Any:
        return self.policy.act_batch(obs, *neighbour_index)

    def reset(self, batch_size: int = 1, seeds: Sequence[int | None] | None = None) -> None:
        if callable(getattr(self.policy, "reset", None)):
            self.policy.reset(batch_size, seeds=seeds)

    def records(self) -> Any | None:
        records = getattr(self.policy, "records", None)
        return records() if callable(records) else None


def as_batch_policy(policy: Any) -> PolicyBase:
    """``policy`` itself if it derives from :class:`PolicyBase` (every policy of the package),
    else a wrapper that gives it the protocol's defaults (the one place that looks at what a
    foreign policy has)."""
    return policy if isinstance(policy, PolicyBase) else _Defaults(policy)
