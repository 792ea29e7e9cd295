"""The foreign study's 2-D grids (DMDA-style, Neumann, log-normal) at about 1 000 to 30 000 rows: their own order's
bandwidth, reverse Cuthill-McKee's, and whether band.ordering now keeps the own order without the search (its
bandwidth at most the square root of the rows, which most rows span). From the repository root:
  python results/small-20261128/widths.py > results/small-20261128/widths.txt"""
import numpy as np
import scipy.sparse as sp

from petsc_htp.bench.foreigncases import CASES
from petsc_htp.twolevel.band import _spanned, own_width
from petsc_htp.twolevel.cuthill import reverse_cuthill_mckee

for case in ("dmda2d", "neumann", "lognormal"):
    for n in (1000, 2000, 8000, 30000):
        A = sp.csr_matrix(CASES[case](n, 0)[0])
        A.sort_indices()
        own, perm = own_width(A), reverse_cuthill_mckee(A)
        inverse = np.empty_like(perm)
        inverse[perm] = np.arange(perm.size)
        row = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        rcm = int(np.abs(inverse[row] - inverse[A.indices]).max())
        kept = own * own <= A.shape[0] and _spanned(A, own)
        print(f"{case} {A.shape[0]} rows: own bandwidth {own}, RCM's {rcm}, own order kept without the search: {kept}")
