#!/bin/sh
# variety.py (HTPPC as it comes) at each commit of COMMITS in turn, REPS rounds, then the two-level method and GAMG at
# the last (2026-11-29, this 2-core AMD EPYC, one thread). From the repository root:
#   sh results/threed-20261129/least.sh "C1 C2 ..." SIDE REPS > results/threed-20261129/least.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
COMMITS=$1; SIDE=${2:-50}; REPS=${3:-2}
. results/abtrees.sh
for r in $(seq $REPS); do
  for c in $COMMITS; do
    PYTHONPATH="$TREES/$c" $P results/threed-20261129/variety.py $SIDE default | grep -v "Linear solve" | sed "s/^/$c run $r: /"
  done
done
LAST=${COMMITS##* }
PYTHONPATH="$TREES/$LAST" $P results/threed-20261129/variety.py $SIDE twolevel gamg | grep -v "Linear solve" | sed "s/^/$LAST: /"
trees_remove
