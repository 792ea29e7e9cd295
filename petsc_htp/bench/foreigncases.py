"""The matrices of the ``foreign`` study: families other programs hand over, sized to about N unknowns.

Each case is ``make(n, frame) -> (A, b)``: frame 0 is the single solve; later frames keep the pattern and change
the values (new coefficients, a turned anisotropy, a heat step's new time step), except the free surface, whose
liquid moves, so each frame has a pattern of its own. PyAMG's shipped examples have their own size and no frames.
"""
from __future__ import annotations

import math

import numpy as np

from ..scenes import foreign, meshes

LIQUID = 0.47           # the free surface's share of liquid cells in its box


def _side(n, dim) -> int:
    return max(4, int(round(n ** (1.0 / dim))))


CASES = {
    "dmda2d": lambda n, k: foreign.dmda(2, _side(n, 2), 1e3, k),
    "dmda3d": lambda n, k: foreign.dmda(3, _side(n, 3), 1e3, k),
    "free_surface": lambda n, k: foreign.free_surface(int(round(math.sqrt(n / LIQUID))), k),
    "aniso_e0.01_a30": lambda n, k: foreign.anisotropic(_side(n, 2), 0.01, np.pi / 6, k),
    "aniso_e0.001_a45": lambda n, k: foreign.anisotropic(_side(n, 2), 0.001, np.pi / 4, k),
    "fem_tri": lambda n, k: meshes.p1_laplacian(2, n, 0, k),
    "fem_tet": lambda n, k: meshes.p1_laplacian(3, n, 0, k),
    "fem_hex": lambda n, k: meshes.q1_laplacian(n, k),
    "lognormal": lambda n, k: foreign.lognormal(_side(n, 2), 1e10, k),
    "neumann": lambda n, k: foreign.neumann(_side(n, 2), 1e3, k),
    "heat_tet": lambda n, k: meshes.p1_heat(3, n, 10.0, 0, k),
}
PATTERN_CHANGES = ("free_surface",)


def pyamg_cases() -> dict:
    """PyAMG's shipped SPD examples as cases (one frame each), with a random right-hand side, made mean-free where
    the matrix is singular (its row sums vanish: unit_square), so that the system is consistent."""
    out = {}
    for name, A in foreign.pyamg_examples().items():
        b = np.random.default_rng(0).standard_normal(A.shape[0])
        if np.abs(A.sum(axis=1)).max() <= 1e-10 * np.abs(A.diagonal()).max():
            b -= b.mean()
        out[f"pyamg_{name}"] = (A, b)
    return out
