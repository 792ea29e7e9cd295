"""The few collectives HTPPC needs (one helper for the whole plugin), through mpi4py only on more than one rank.

Every decision that changes which collectives run next (a new analysis, an error) is taken from reduced values,
so all ranks take the same branch.
"""
from __future__ import annotations

import numpy as np


class Collective:
    """Reductions over the ranks of a PETSc communicator ``comm``."""

    def __init__(self, comm):
        self.size = comm.getSize()
        self.mpi = comm.tompi4py() if self.size > 1 else None

    def exscan(self, value: int) -> int:
        """Sum of ``value`` over the lower ranks."""
        return 0 if self.mpi is None else (self.mpi.exscan(int(value)) or 0)

    def sum(self, value: int) -> int:
        """Sum of ``value`` over the ranks."""
        return int(value) if self.mpi is None else self.mpi.allreduce(int(value))

    def any(self, flag) -> bool:
        """``flag`` or'ed over the ranks."""
        return bool(self.sum(1 if flag else 0))

    def _array(self, values: np.ndarray, op: str) -> np.ndarray:
        if self.mpi is None:
            return values
        from mpi4py import MPI

        out = np.empty_like(values)
        self.mpi.Allreduce(np.ascontiguousarray(values), out, op=getattr(MPI, op))
        return out

    def max_array(self, values: np.ndarray) -> np.ndarray:
        """Entrywise maximum of ``values`` over the ranks."""
        return self._array(values, "MAX")

    def min_array(self, values: np.ndarray) -> np.ndarray:
        """Entrywise minimum of ``values`` over the ranks."""
        return self._array(values, "MIN")

    def sum_array(self, values: np.ndarray) -> np.ndarray:
        """Entrywise sum of ``values`` over the ranks."""
        return self._array(values, "SUM")

    def gather_rows(self, values: np.ndarray) -> np.ndarray:
        """Every rank's rows of a 2-column int array, concatenated in rank order."""
        if self.mpi is None:
            return values
        return np.concatenate(self.mpi.allgather(values)).reshape(-1, values.shape[1])
