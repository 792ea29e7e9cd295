#!/bin/sh
# HTPPC as it comes after the 2-D coarse size of 5 000 rows (commit ea1b881; 2026-11-28, this 2-core AMD EPYC, one
# thread per rank), from the repository root: the foreign study's 2-D cases at 65 536 rows with the baselines swept
# (foreign/).
#   sh results/multilevel-20261128h/run.sh
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
D=results/multilevel-20261128h
$P -m petsc_htp.bench --studies foreign --methods cg_htp cg_gamg cg_gamg_default gamg_t0.05_a1 amgcl amgcl_ce500 \
    amgcl_ce1000 --foreign-scales 65536 --foreign-cases dmda2d free_surface lognormal neumann --foreign-frames 2 \
    --threads 1 --out $D/foreign --no-progress
