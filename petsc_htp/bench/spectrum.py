"""Eigenvalues of the preconditioned operator M A on one small frame (dense, N around 1024)."""
from __future__ import annotations

import numpy as np

from .aggregate import condition_number


def dense_operator(apply, n) -> np.ndarray:
    """The n x n matrix of a linear map, column by column."""
    eye = np.eye(n)
    return np.column_stack([apply(eye[:, i]) for i in range(n)])


def preconditioned_eigs(A, M=None):
    """Eigenvalues of M A without the null-space one; and whether M A has non-positive eigenvalues.

    With a symmetric positive-definite part ``(M + M^T)/2 = L L^T`` the
    spectrum is that of the symmetric ``L^T A L``; otherwise the real parts
    of the eigenvalues of ``M A``. The eigenvalue of smallest magnitude (the
    constant null vector of the Neumann operator) is dropped.
    """
    A = np.asarray(A.toarray() if hasattr(A, "toarray") else A, dtype=float)
    if M is None:
        eigs = np.linalg.eigvalsh(A)
    else:
        try:
            L = np.linalg.cholesky((M + M.T) / 2)
            eigs = np.linalg.eigvalsh(L.T @ A @ L)
        except np.linalg.LinAlgError:
            eigs = np.sort(np.linalg.eigvals(M @ A).real)
    eigs = np.delete(eigs, np.argmin(np.abs(eigs)))
    return np.sort(eigs), bool(eigs.min() <= 0)


def spectrum_row(name, frame, M=None) -> dict:
    """One row: the spectrum of M A on ``frame`` with its condition number."""
    eigs, indefinite = preconditioned_eigs(frame.A, M)
    asym = 0.0 if M is None else float(np.linalg.norm(M - M.T) / np.linalg.norm(M))
    return {"method": name, "n": frame.n, "seed": frame.params.get("seed"), "eigs": eigs.tolist(),
            "kappa": condition_number(eigs), "indefinite": indefinite, "asymmetry": asym}


def petsc_operator(method, frame) -> np.ndarray:
    """The dense M of a method's PC (an options-file name) on ``frame``, geometry attached, through PETSc."""
    from petsc4py import PETSc

    from .harness import Loaded
    from ..petscmat import attach, frame_mat

    A = frame_mat(frame)
    attach(A, coords=frame.coords, density=frame.rho)
    with Loaded(method, prefix="spectrum_"):
        pc = PETSc.PC().create(A.getComm())
        pc.setOptionsPrefix("spectrum_")
        pc.setOperators(A, A)
        pc.setFromOptions()
        pc.setUp()
    x, y = A.createVecs()

    def apply(v):
        x.array_w[...] = v
        pc.apply(x, y)
        return y.array_r.copy()

    try:
        return dense_operator(apply, frame.n)
    finally:
        for obj in (pc, x, y, A):
            obj.destroy()


def spectrum_rows(frame, htp=None, methods=()) -> list:
    """Spectra of A (no preconditioner), D^-1 A (Jacobi), with a loaded HTP its M A, and M A of ``methods``."""
    rows = [spectrum_row("none", frame), spectrum_row("jacobi", frame, np.diag(1.0 / frame.A.diagonal()))]
    if htp is not None:
        setup = htp.setup(frame.A, coords=frame.coords, density=frame.rho)
        rows.append(spectrum_row("htp", frame, dense_operator(setup.apply, frame.n)))
    return rows + [spectrum_row(m, frame, petsc_operator(m, frame)) for m in methods]
