#!/bin/sh
# The scale study of issue #25 (2026-11-28, this 2-core AMD EPYC, one thread per rank), from the repository root:
#   sh results/scale-20261128/run.sh
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
${PYTHON:-.venv/bin/python} -m petsc_htp.bench --studies scale --methods cg_htp cg_gamg cg_gamg_default gamg_t0.05_a1 \
    amgcl amgcl_ce500 amgcl_ce1000 --scale-sides-2d 256 1024 2048 --scale-sides-3d 32 64 128 --scale-ranks 1 2 \
    --scale-frames 3 --threads 1 --out results/scale-20261128 --no-progress
