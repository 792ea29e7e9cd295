#!/bin/sh
# variety.py (HTPPC as it comes) at commits OLD and NEW in turn, REPS rounds, and the two-level method and GAMG at NEW
# (2026-11-29, this 2-core AMD EPYC, one thread). From the repository root:
#   sh results/threed-20261129/decay.sh OLD NEW SIDE REPS > results/threed-20261129/decay.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; SIDE=${3:-50}; REPS=${4:-2}
COMMITS="$OLD $NEW"
. results/abtrees.sh
for r in $(seq $REPS); do
  for c in $OLD $NEW; do
    PYTHONPATH="$TREES/$c" $P results/threed-20261129/variety.py $SIDE default | sed "s/^/$c run $r: /"
  done
done
PYTHONPATH="$TREES/$NEW" $P results/threed-20261129/variety.py $SIDE twolevel gamg | sed "s/^/$NEW: /"
trees_remove
