#!/bin/sh
# The plain DMDA program (examples/dmda_poisson.py, one solve after a warm-up) at N^2 on 1 and 2 ranks at commits OLD
# and NEW, REPS runs in turn (2026-11-28, this 2-core AMD EPYC, one thread). From the repository root:
#   sh results/robust-20261128/ranks_ab.sh OLD NEW N REPS > results/robust-20261128/ranksN.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=$(pwd)/.venv/bin/python
OLD=$1; NEW=$2; N=$3; REPS=$4
COMMITS="$OLD $NEW"
. results/abtrees.sh
for run in $(seq $REPS); do
  for c in $OLD $NEW; do
    for r in 1 2; do
      printf "n=%s c=%s ranks=%s run=%s: " $N $c $r $run
      mpiexec -n $r $P $TREES/$c/examples/dmda_poisson.py -n $N -warmup $HTP | grep -E "^iterations|^setup ms|^solve ms" | tr '\n' ' '
      echo
    done
  done
done
trees_remove
