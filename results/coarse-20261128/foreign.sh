#!/bin/sh
# The foreign study's 2-D cases at 65 536 rows with the baselines swept, HTPPC as it comes with the coarsest level's
# banded Cholesky factor (2026-11-28, this 2-core AMD EPYC, one thread). From the repository root:
#   sh results/coarse-20261128/foreign.sh OUT          (OUT: foreign at commit f1dea24, foreign2 at 24959cf)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
$P -m petsc_htp.bench --studies foreign --methods cg_htp cg_gamg cg_gamg_default gamg_t0.05_a1 amgcl amgcl_ce500 \
    amgcl_ce1000 --foreign-scales 65536 --foreign-cases dmda2d free_surface lognormal neumann fem_tri \
    --foreign-frames 2 --threads 1 --out results/coarse-20261128/${1:-foreign} --no-progress
