#!/bin/sh
# The foreign study's 3-D and anisotropic cases at about 65 536 rows with the baselines swept (2026-11-28, this 2-core
# AMD EPYC, one thread); then the project's own frames in sequence mode against AMGCL with its coarse size swept.
# From the repository root:  sh results/refill-20261128/foreign3d.sh
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
$P -m petsc_htp.bench --studies foreign --methods cg_htp cg_gamg cg_gamg_default gamg_t0.05_a1 amgcl amgcl_ce500 \
    amgcl_ce1000 --foreign-scales 65536 --foreign-cases dmda3d fem_tet aniso_e0.01_a30 aniso_e0.001_a45 \
    --foreign-frames 2 --threads 1 --out results/refill-20261128/foreign3d --no-progress
$P -m petsc_htp.bench --studies sequence --methods cg_htp cg_gamg amgcl amgcl_ce500 amgcl_ce1000 \
    --seq-scales 16384 65536 --seq-frames 10 --threads 1 --out results/refill-20261128/own --no-progress
