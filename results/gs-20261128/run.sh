#!/bin/sh
# The 2-D smoother and the multilevel choice's sizes (2026-11-28, this 2-core AMD EPYC, one thread; single solves,
# the least of REPS, methods in turn). From the repository root:
#   sh results/gs-20261128/run.sh > results/gs-20261128/run.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
S=results/gs-20261128/solve.py
for r in 1 2 3; do                                                   # the smoother, in turn
  for c in dmda2d free_surface lognormal neumann; do
    for s in jacobi gs; do $P $S $c 65536 3 htp_ml_smoother=$s | tail -1; done
  done
  for s in jacobi gs; do $P $S dmda2d 1048576 1 htp_ml_smoother=$s | tail -1; done
done
for n in 16384 32768; do                                             # two-level against the V-cycles
  for c in dmda2d lognormal neumann fem_tri; do
    for v in twolevel multilevel; do $P $S $c $n 4 htp_variant=$v | tail -1; done
  done
done
for n in 65536 262144; do
  for v in twolevel multilevel; do $P $S fem_tri $n 3 htp_variant=$v | tail -1; done
done
for v in twolevel multilevel; do $P $S fem_tri 1048576 1 htp_variant=$v | tail -1; done
