"""Random streams for a flat batch of optimisation problems: one per scenario copy
(:class:`RowStreams`, numpy generators on the host) or one per problem (:class:`CounterStreams`,
counter-based draws on the problems' device).

A batched policy solves the triggered problems of every copy in one optimiser call. If they all
drew from one generator, copy b's draws would depend on how many problems the other copies had
before it, and the same seed would fly differently alone and inside a batch. :class:`RowStreams`
stands in for the generator: the rows (problems) of each copy are drawn from that copy's own
generator, so copy b's numbers depend only on its own seed and its own problems.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from uav_formation_env.core import counter_rng
from uav_formation_env.core.array_api import device, namespace_of


class RowStreams:
    """A ``numpy.random.Generator`` stand-in whose rows come from per-copy generators.

    Rows ``0 .. counts[0]-1`` of every draw come from ``generators[0]``, the next ``counts[1]``
    rows from ``generators[1]``, and so on (the flat problem batch is ordered by copy). A copy with
    one generator and all the rows draws exactly what the generator alone would.

    Args:
        generators: one generator per copy that has rows.
        counts: rows (problems) of each copy; 0 skips the copy.
    """

    def __init__(self, generators: Sequence[np.random.Generator], counts: Sequence[int]) -> None:
        if len(generators) != len(counts):
            raise ValueError(
                f"need one row count per generator, got {len(counts)} for {len(generators)}"
            )
        keep = [(g, int(c)) for g, c in zip(generators, counts) if c > 0]
        self.generators = [g for g, _ in keep]
        self.counts = [c for _, c in keep]
        self.bounds = np.concatenate(([0], np.cumsum(self.counts, dtype=np.int64)))

    @property
    def rows(self) -> int:
        """Total number of rows."""
        return int(self.bounds[-1])

    def random(self, size: tuple[int, ...]) -> np.ndarray:
        """U[0, 1) of shape ``size`` whose first axis is the rows."""
        self._check(size[0], "size[0]")
        if len(self.generators) == 1:
            return self.generators[0].random(size)
        return np.concatenate(
            [g.random((c, *size[1:])) for g, c in zip(self.generators, self.counts)]
        )

    def standard_normal(self, out: np.ndarray) -> np.ndarray:
        """Fill ``out`` ``(K, rows, ...)`` (the Lévy buffer: K = 2 for mu and nu) with N(0, 1).

        Each copy draws its ``(K, count, ...)`` block in one call, so K = 2 gives the copy's mu
        then its nu, as one generator filling a one-copy buffer does.
        """
        self._check(out.shape[1], "out.shape[1]")
        if len(self.generators) == 1:
            return self.generators[0].standard_normal(out=out)
        for g, c, start in zip(self.generators, self.counts, self.bounds):
            out[:, start : start + c] = g.standard_normal((out.shape[0], c, *out.shape[2:]))
        return out

    def _check(self, rows: int, name: str) -> None:
        if rows != self.rows:
            raise ValueError(f"{name} must be the {self.rows} rows of the streams, got {rows}")


class CounterStreams:
    """A ``numpy.random.Generator`` stand-in whose numbers are Philox counter draws
    (:mod:`uav_formation_env.core.counter_rng`), computed in the library and on the device of
    its keys.

    Row r's numbers are a function of its key, its two labels and the draw index only (the
    draws of one :func:`~uav_formation_env.policies.optimizers.minimise` call are numbered from
    ``first_draw``): they do not depend on the other rows, and numpy and torch give the same
    uniforms bit for bit (normals to an ulp).

    Args:
        keys: (rows, 2) int64 key words of each row (e.g. its episode's seed).
        labels: (rows, 2) int64 counter words of each row in [0, 2^32) (e.g. UAV, step).
        first_draw: the draw index of the first call (e.g. distinct per inner round).
    """

    def __init__(self, keys: Any, labels: Any, first_draw: int = 0) -> None:
        if keys.ndim != 2 or keys.shape[1] != 2 or tuple(labels.shape) != tuple(keys.shape):
            raise ValueError(
                f"keys and labels must both be (rows, 2), got {tuple(keys.shape)} and "
                f"{tuple(labels.shape)}"
            )
        self.keys, self.labels, self.draw = keys, labels, int(first_draw)

    @property
    def rows(self) -> int:
        """Total number of rows."""
        return int(self.keys.shape[0])

    def _words(self) -> Any:
        xp = namespace_of(self.keys)
        draw = xp.full((self.rows, 1), self.draw, dtype=self.keys.dtype, device=device(self.keys))
        self.draw += 1
        return xp.concat((draw, self.labels), axis=1)

    def random(self, size: tuple[int, ...]) -> Any:
        """U[0, 1) of shape ``size`` whose first axis is the rows (on the keys' device)."""
        if size[0] != self.rows:
            raise ValueError(f"size[0] must be the {self.rows} rows of the streams, got {size[0]}")
        return counter_rng.uniform(self.keys, self._words(), tuple(size[1:]))

    def standard_normal(self, out: Any) -> Any:
        """Fill ``out`` ``(K, rows, ...)`` (numpy or a tensor) with N(0, 1); K = 2 for the Lévy
        steps' mu and nu."""
        if out.shape[1] != self.rows:
            raise ValueError(
                f"out.shape[1] must be the {self.rows} rows of the streams, got {out.shape[1]}"
            )
        drawn = counter_rng.standard_normal(
            self.keys, self._words(), (out.shape[0], *out.shape[2:])
        )  # (rows, K, ...)
        xp = namespace_of(drawn)
        out[...] = xp.permute_dims(drawn, (1, 0, *range(2, drawn.ndim)))
        return out


RandomSource = np.random.Generator | RowStreams | CounterStreams  # what the optimisers draw from
