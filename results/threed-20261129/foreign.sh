#!/bin/sh
# The foreign study's 3-D DMDA case at about 64 000 and 1M rows with the baselines swept (2026-11-29, this 2-core AMD
# EPYC, one thread). From the repository root:  sh results/threed-20261129/foreign.sh SCALE
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
$P -m petsc_htp.bench --studies foreign --methods cg_htp cg_gamg cg_gamg_default gamg_t0.05_a1 amgcl amgcl_ce500 \
    amgcl_ce1000 --foreign-scales $1 --foreign-cases dmda3d --foreign-frames 2 --threads 1 \
    --out results/threed-20261129/foreign$1 --no-progress
