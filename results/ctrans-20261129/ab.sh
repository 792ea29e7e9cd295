#!/bin/sh
# The project's own frames in sequence mode at commits OLD and NEW, run in turn REPS times at N = 16 384 and 65 536
# (results/ctrans-20261129/frames.py; 2026-11-29, this 2-core AMD EPYC, one thread), then NEW's C^T products.
# From the repository root:  sh results/ctrans-20261129/ab.sh OLD NEW REPS > results/ctrans-20261129/ab.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; REPS=${3:-3}
COMMITS="$OLD $NEW"
. results/abtrees.sh
for r in $(seq $REPS); do
  for n in 16384 65536; do
    for c in $OLD $NEW; do
      printf "N=%s run %s %s " $n $r $c
      (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/ctrans-20261129/frames.py" $n)
    done
  done
done
for n in 16384 65536; do
  (cd /tmp && PYTHONPATH="$TREES/$NEW" $P "$OLDPWD/results/ctrans-20261129/frames.py" $n micro)
done
trees_remove
