#!/bin/sh
# The coarse solve of the multilevel V-cycle: sparse LU against LAPACK's banded Cholesky on the coarsest operators of
# the DMDA matrices (2026-11-28, this 2-core AMD EPYC, one thread; run at commit f1dea24). From the repository root:
#   sh results/coarse-20261128/run.sh > results/coarse-20261128/band.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
for args in "256 5000" "1024 5000" "2048 5000" "1024 60000" "64 1000 3" "64 5000 3"; do
  $P results/coarse-20261128/band.py $args
done
