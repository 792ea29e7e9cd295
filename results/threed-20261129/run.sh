#!/bin/sh
# 3-D bare matrices at commits OLD and NEW, run in turn REPS times (2026-11-29, this 2-core AMD EPYC, one thread per
# rank): the plain DMDA program (examples/dmda_poisson.py -dim 3, one solve after a warm-up, HTPPC as it comes, and
# PETSc's GAMG with the project's tuned options file) at sides 44 and 64 on 1 and 2 ranks; then the foreign study's
# dmda3d and fem_tet frames (results/bound-20261128/frames.py: frame 0 a fresh KSP, then 3 more with new values).
# From the repository root:  sh results/threed-20261129/run.sh OLD NEW REPS > results/threed-20261129/run.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; REPS=${3:-2}
COMMITS="$OLD $NEW"
. results/abtrees.sh
for r in $(seq $REPS); do
  for n in 44 64; do
    for ranks in 1 2; do
      for c in $OLD $NEW gamg; do
        printf "dmda_poisson -dim 3 -n %s ranks=%s %s run=%s: " $n $ranks $c $r
        if [ $c = gamg ]; then opts="-options_file options/cg_gamg.opts"; tree=$TREES/$NEW; else opts=$HTP; tree=$TREES/$c; fi
        mpiexec -n $ranks $P "$tree/examples/dmda_poisson.py" -dim 3 -n $n -warmup $opts | grep -E "^iterations|^setup ms|^solve ms" | tr '\n' ' '
        echo
      done
    done
  done
done
for r in $(seq $REPS); do
  for case in "dmda3d 32768" "dmda3d 64000" "dmda3d 125000" "fem_tet 64000"; do
    for c in $OLD $NEW; do
      printf "%s %s run %s: " "$case" $c $r
      (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/bound-20261128/frames.py" ${case#* } 3 ${case% *} | sed 's/^[^:]*: //')
    done
  done
done
for c in $OLD $NEW; do
  printf "dmda3d 1000000 %s: " $c
  (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/bound-20261128/frames.py" 1000000 2 dmda3d | sed 's/^[^:]*: //')
done
trees_remove
