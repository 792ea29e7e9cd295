#!/bin/sh
# Log-normal edge weights exp(SIGMA N(0, 1)) on 100^2 and 180^2 cells (edges.py), HTPPC at commits OLD and NEW, and
# PETSc's Cholesky (nested dissection) as the reference of what the matrix's precision allows (2026-11-28, this 2-core
# AMD EPYC, one thread). From the repository root:
#   sh results/robust-20261128/edges_ab.sh OLD NEW > results/robust-20261128/edges.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2
COMMITS="$OLD $NEW"
. results/abtrees.sh
for side in 100 180; do
  for sigma in 5 6 7 8; do
    for c in $OLD $NEW; do
      printf "%s " $c; (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/robust-20261128/edges.py" $side $sigma)
    done
    printf "petsc "; $P results/robust-20261128/edges.py $side $sigma pc_type=cholesky pc_factor_mat_ordering_type=nd
  done
done
trees_remove
