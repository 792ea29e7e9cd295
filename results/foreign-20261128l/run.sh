#!/bin/sh
# HTPPC as it comes after each rank's own Galerkin products (multilevel/galerkin.py), commit 611dcb5 (2026-11-28, this
# 2-core AMD EPYC, one thread per rank), from the repository root: the foreign study's 2-D cases at 65 536 rows with
# the baselines swept.
#   sh results/foreign-20261128l/run.sh
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
D=results/foreign-20261128l
$P -m petsc_htp.bench --studies foreign --methods cg_htp cg_gamg cg_gamg_default gamg_t0.05_a1 amgcl amgcl_ce500 \
    amgcl_ce1000 --foreign-scales 65536 --foreign-cases dmda2d free_surface lognormal neumann fem_tri \
    --foreign-frames 2 --threads 1 --out $D --no-progress
