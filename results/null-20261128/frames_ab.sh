#!/bin/sh
# Foreign cases' frames (results/bound-20261128/frames.py: frame 0 a fresh KSP, then FRAMES more with new values on
# the same KSP) at commits OLD and NEW, run in turn REPS times, HTPPC as it comes (2026-11-28, this 2-core AMD EPYC,
# one thread). From the repository root:
#   sh results/null-20261128/frames_ab.sh OLD NEW N FRAMES REPS CASE... > results/null-20261128/OUT.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; N=$3; FRAMES=$4; REPS=$5
shift 5
COMMITS="$OLD $NEW"
. results/abtrees.sh
for case in "$@"; do
  for r in $(seq $REPS); do
    for c in $OLD $NEW; do
      printf "%s %s %s run %s: " "$case" $N $c $r
      (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/bound-20261128/frames.py" $N $FRAMES "$case" | sed 's/^[^:]*: //')
    done
  done
done
trees_remove
