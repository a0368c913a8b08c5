"""One random stream per scenario copy for a flat batch of optimisation problems.

A batched policy solves the triggered problems of every copy in one optimiser call. If they all
drew from one generator, copy b's draws would depend on how many problems the other copies had
before it, and the same seed would fly differently alone and inside a batch. :class:`RowStreams`
stands in for the generator: the rows (problems) of each copy are drawn from that copy's own
generator, so copy b's numbers depend only on its own seed and its own problems.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


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


RandomSource = np.random.Generator | RowStreams  # what the optimisers draw from
