"""The terms of the section's total potential; ``SectionProblem`` (problem.py) sums them.

A term is an object with
    dofs                          (b, m) int array: the global unknowns of each of its b blocks;
                                  fixed, so the problem builds the sparsity pattern from it once
    energy(x, pressures)          its share of the potential (float); +inf if x is inadmissible
    assemble(x, pressures)        a ``Contribution``: energy, gradient (b, m), Hessian (b, m, m)

``x`` is the problem's state [u (2 n_nodes, / R), lambda, kx R, ky R, element pressures / c1]
and ``pressures`` the channel pressures / c1. Adding a term (contact, say) is writing one module
with this interface and listing it in ``SectionProblem``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass
class Contribution:
    """A term's energy with its per-block gradient and Hessian (None where the state is
    inadmissible, energy inf); ``condensation``: what a term with statically condensed
    unknowns (the silicone's element pressures) needs for their update."""

    energy: float
    gradient: np.ndarray | None = None
    hessian: np.ndarray | None = None
    condensation: tuple | None = None


class SparseContribution(Contribution):
    """A one-block term's contribution whose Hessian is mostly zero (wall contact: only the pairs
    within the barrier's range), given by its non-zero entries: ``keys`` (flat indices into the
    (size, size) block, unique) and ``values``. The problem scatters only those; ``hessian`` is the
    dense block, built when asked for."""

    def __init__(self, energy: float, gradient: np.ndarray, keys: np.ndarray, values: np.ndarray, size: int):
        super().__init__(energy, gradient)
        self.keys, self.values, self.size = keys, values, size

    @property
    def hessian(self) -> np.ndarray:
        H = np.zeros(self.size * self.size)
        H[self.keys] = self.values
        return H.reshape(1, self.size, self.size)

    @hessian.setter
    def hessian(self, value) -> None:      # the dataclass's __init__ sets it to None: built from the entries
        pass


INADMISSIBLE = Contribution(np.inf)


class Term(Protocol):
    dofs: np.ndarray

    def energy(self, x: np.ndarray, pressures: np.ndarray) -> float: ...

    def assemble(self, x: np.ndarray, pressures: np.ndarray) -> Contribution: ...
