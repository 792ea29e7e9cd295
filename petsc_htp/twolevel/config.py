"""What the two-level method is made of: HTPPC's ``-htp_*`` options that shape it."""
from __future__ import annotations

from dataclasses import dataclass

COARSE_TEXT = {"const": "the constant of each piece of each leaf",
               "eig": "piece constants and one inverse-iteration step of each leaf's Neumann matrix from smooth seeds",
               "learned": "piece constants and the coarse network's vectors refined by the same step as eig"}


@dataclass(frozen=True)
class Config:
    """The two-level method's configuration.

    Attributes
    ----------
    leaf : int
        Rows per leaf; 0: by the problem's dimension (:mod:`petsc_htp.twolevel.sizing`).
    ordering : str
        Leaf layout: auto, aggregation, morton, metis, natural or rcm (:func:`petsc_htp.twolevel.leaves.choose_leaves`).
    aggregation : str
        Aggregation leaves' passes after the first: standard, pairs or auto (by the problem's dimension).
    coarse : str
        const, eig, learned or auto (by the problem's dimension).
    rank : int
        Vectors per leaf r: the piece constants and r - 1 more (eig; learned takes the network's r).
    tol : float
        With tol > 0, r more seeds per leaf, kept by their Ritz value (see :mod:`petsc_htp.twolevel.coarsespace`).
    form : str
        auto (deflated; balanced under a KSP that needs a symmetric M, or where the coarse solve is one V-cycle, a
        loose one, or V-cycles under overlapping leaves),
        deflated or balanced.
    overlap : int
        0: exact leaf solves; k > 0: additive Schwarz on leaves grown by k layers (:mod:`petsc_htp.twolevel.leafsolvers`).
    solver : str
        Coarse solver: lu, gamg or auto (by the coarse operator's size and dimension).
    block_size : int
        Unknowns per node; 0: the Mat's, else found in the pattern (:mod:`petsc_htp.twolevel.blocksize`).
    """

    leaf: int = 0
    ordering: str = "auto"
    coarse: str = "auto"
    rank: int = 4
    tol: float = 0.0
    form: str = "auto"
    overlap: int = 0
    solver: str = "auto"
    aggregation: str = "auto"
    block_size: int = 0
