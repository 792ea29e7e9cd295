#!/usr/bin/env python
"""A plain PETSc program, as PETSc's KSP tutorial ex10: one matrix, one solve, any KSP and PC, any number of ranks.

    mpiexec -n 2 python examples/matrix_file.py -f A.petsc -ksp_type cg -ksp_rtol 1e-8 \\
        -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC
    mpiexec -n 2 python examples/matrix_file.py -case fem_tri -n 65536 -options_file options/cg_gamg.opts

``-f FILE`` loads a matrix (and, where the file holds one after it, a right-hand side) in PETSc's binary format
with MatLoad; ``-case NAME -n N`` takes one of the benchmark's foreign-study matrices instead
(:mod:`petsc_htp.bench.foreigncases`: ``dmda2d``, ``fem_tri``, ...; its own right-hand side), in its own row order:
the P1 meshes number their nodes at random, so a contiguous split hands each rank rows from all over the mesh. Each
rank owns a contiguous block of rows, as MatLoad gives them; ``-write FILE`` saves the matrix and right-hand side
for other programs. A loaded matrix whose row sums vanish gets the constant null space attached (a generated one
the constant of each region whose row sums vanish, flagged symmetric). ``-warmup`` solves the
same case at 4096 rows first (``-case`` only), so that one-time costs (imports, first calls) stay out of the timed
solve. Prints the iterations, PETSc's reason, the setup (KSPSetUp) and solve milliseconds, the true relative
residual and the peak resident memory of the largest rank; exits non-zero when the solve did not converge.
"""
import resource
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv)
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.onesolve import solve_once  # noqa: E402
from petsc_htp.petscmat import frame_mat, frame_vec  # noqa: E402


def generated(case, n, comm):
    """The foreign-study matrix ``case`` of about ``n`` rows (each rank setting its own contiguous block of rows,
    flagged symmetric, a null space attached where a region's row sums vanish) and its right-hand side."""
    from petsc_htp.bench.foreigncases import CASES
    from petsc_htp.bench.studies.foreign import bare_frame

    if case not in CASES:
        raise SystemExit(f"-case must be one of {', '.join(CASES)}, got {case!r}")
    frame = bare_frame(*CASES[case](n, 0), case)
    mat = frame_mat(frame, comm)
    return mat, frame_vec(frame, mat)


def loaded(path, comm):
    """The matrix in the binary file ``path`` (MatLoad) and the vector after it, else a vector of ones."""
    viewer = PETSc.Viewer().createBinary(path, "r", comm=comm)
    mat = PETSc.Mat().create(comm)
    mat.setType(PETSc.Mat.Type.AIJ)
    mat.load(viewer)
    rhs = mat.createVecLeft()
    try:
        rhs.load(viewer)
    except PETSc.Error:
        rhs.set(1.0)
    viewer.destroy()
    return mat, rhs


def with_null_space(mat):
    """Attach the constant null space where every row sum vanishes (a Neumann matrix); whether it did."""
    ones = mat.createVecRight()
    ones.set(1.0)
    sums = mat.createVecLeft()
    mat.mult(ones, sums)
    diag = mat.getDiagonal()
    singular = sums.norm(PETSc.NormType.INFINITY) <= 1e-10 * diag.norm(PETSc.NormType.INFINITY)
    if singular:
        mat.setNullSpace(PETSc.NullSpace().create(constant=True, comm=mat.getComm()))
    for vec in (ones, sums, diag):
        vec.destroy()
    return singular


def main():
    db, comm = PETSc.Options(), PETSc.COMM_WORLD
    path, case = db.getString("f", ""), db.getString("case", "")
    if bool(path) == bool(case):
        raise SystemExit("give a matrix file (-f FILE) or a foreign-study case (-case NAME -n N), one of them")
    if case and db.getBool("warmup", False):
        warm = generated(case, 4096, comm)
        solve_once(*warm)
        for obj in warm:
            obj.destroy()
    mat, rhs = loaded(path, comm) if path else generated(case, db.getInt("n", 65536), comm)
    out = db.getString("write", "")
    if out:
        viewer = PETSc.Viewer().createBinary(out, "w", comm=comm)
        mat.view(viewer)
        rhs.view(viewer)
        viewer.destroy()
    null = with_null_space(mat) if path else bool(mat.getNullSpace().handle)   # a file's matrix: not flagged
    its, reason, setup, solve_ms, relres = solve_once(mat, rhs)
    peak = comm.tompi4py().allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, op=MPI.MAX) / 1024.0
    note = "; constant null space attached" if null else ""
    PETSc.Sys.Print(f"rows: {mat.getSize()[0]} on {comm.getSize()} rank(s){note}\n"
                    f"iterations: {its}\nconverged reason: {reason}\nsetup ms (KSPSetUp): {setup:.1f}\n"
                    f"solve ms: {solve_ms:.1f}\ntrue relative residual ||b - A x|| / ||b||: {relres:.3e}\n"
                    f"peak RSS of the largest rank, MiB: {peak:.0f}")
    return 0 if reason > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
