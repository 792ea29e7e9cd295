#!/bin/sh
# Matrices that had defeated HTPPC's V-cycles, at commits OLD and NEW (2026-11-28, this 2-core AMD EPYC, one thread):
# sealed pockets (cases.py; tests/pockets_case.py on 1 and 2 ranks), the DMDA program handing over D A D (-scale_rows 2,
# unknowns in mixed units, with and without its coefficient jumps), a matrix scaled to 1e+-200, the V-cycles forced on
# a matrix of one level, log-normal edge weights on 1 and 2 ranks (tests/edges_case.py). Iterations, PETSc's reason
# and the true relative residual. From the repository root:
#   sh results/robust-20261128/ab.sh OLD NEW > results/robust-20261128/ab.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2
COMMITS="$OLD $NEW"
. results/abtrees.sh
CASES=$(mktemp -d)
$P results/robust-20261128/cases.py make $CASES              # the matrices, from this tree's generators
for c in $OLD $NEW; do
  for case in pockets16 pockets100 dmda2d scaled1e200 scaled1e-200; do
    printf "%s " $c; (cd /tmp && PYTHONPATH="$TREES/$c" $P "$OLDPWD/results/robust-20261128/cases.py" solve \
      $CASES/$case.npz 2>&1 | sed "s#$TREES/##")
  done
  for r in 1 2; do
    printf "%s ranks %s pockets (tests/pockets_case.py: smoother, reason, iterations, relres): " $c $r
    cp tests/pockets_case.py "$TREES/$c/tests/"          # the case and its generator from this tree, on the tree's
    cp petsc_htp/scenes/foreign.py "$TREES/$c/petsc_htp/scenes/"       # preconditioner
    (cd "$TREES/$c" && mpiexec -n $r $P tests/pockets_case.py | tr '\n' ' '); echo
  done
  for r in 1 2; do
    printf "%s ranks %s log-normal edges (tests/edges_case.py: reason, iterations, relres): " $c $r
    cp tests/edges_case.py "$TREES/$c/tests/"
    (cd "$TREES/$c" && mpiexec -n $r $P tests/edges_case.py)
  done
  for flags in "-n 256 -scale_rows 2" "-n 256 -scale_rows 2 -contrast 1" "-n 256 -contrast 1" \
               "-n 64 -htp_variant multilevel -htp_direct_max 0"; do
    printf "%s dmda_poisson.py %s: " $c "$flags"
    $P "$TREES/$c/examples/dmda_poisson.py" $flags $HTP | grep -E "^iterations|^converged|^true" | tr '\n' ' '
    echo
  done
done
trees_remove
rm -rf $CASES
