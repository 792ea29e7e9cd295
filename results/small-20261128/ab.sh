#!/bin/sh
# solves.py at commits OLD and NEW in turn, REPS rounds (2026-11-28, this 2-core AMD EPYC, one thread). From the
# repository root:  sh results/small-20261128/ab.sh OLD NEW REPS > results/small-20261128/ab.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; REPS=${3:-5}
COMMITS="$OLD $NEW"
. results/abtrees.sh
CASES="pyamg_airfoil pyamg_bar pyamg_local_disc_galerkin_diffusion pyamg_unit_square dmda2d_1000 dmda2d_2000
neumann_1000 lognormal_1000 free_surface_1000 fem_tri_2000"
for r in $(seq $REPS); do
  for c in $OLD $NEW; do
    (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/small-20261128/solves.py" 7 $CASES) | sed "s/^/$c run $r: /"
  done
done
trees_remove
