#!/bin/sh
# P1 triangles numbered at random (the foreign study's fem_tri), N rows, -htp_variant multilevel: a single solve and
# two sequence frames on one KSP (results/bound-20261128/frames.py), at commits OLD and NEW in turn REPS times
# (2026-11-28, this 2-core AMD EPYC, one thread). From the repository root:
#   sh results/bound-20261128/tri_ab.sh OLD NEW N REPS > results/bound-20261128/tri_ab.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; N=${3:-262144}; REPS=${4:-3}
COMMITS="$OLD $NEW"
. results/abtrees.sh
for r in $(seq $REPS); do
  for c in $OLD $NEW; do
    printf "%s run %s: " $c $r
    PYTHONPATH="$TREES/$c" $P results/bound-20261128/frames.py $N 2 fem_tri -htp_variant multilevel
  done
done
trees_remove
