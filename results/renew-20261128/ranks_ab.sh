#!/bin/sh
# The plain DMDA program (examples/dmda_poisson.py, one solve after a warm-up, HTPPC as it comes) on 1 and 2 ranks at
# commits OLD and NEW, run in turn REPS times; each line: commit, grid, ranks, setup and solve ms (2026-11-28, this
# 2-core AMD EPYC, one thread per rank). From the repository root:
#   sh results/renew-20261128/ranks_ab.sh OLD NEW SIDE REPS > results/renew-20261128/ranks_SIDE.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; N=${3:-512}; REPS=${4:-5}
COMMITS="$OLD $NEW"
. results/abtrees.sh
for r in $(seq $REPS); do
  for c in $OLD $NEW; do
    for ranks in 1 2; do
      printf "%s n=%s ranks=%s run=%s: " $c $N $ranks $r
      mpiexec -n $ranks $P "$TREES/$c/examples/dmda_poisson.py" -n $N -warmup $HTP | grep -E "^iterations|^setup ms|^solve ms" | tr '\n' ' '
      echo
    done
  done
done
trees_remove
