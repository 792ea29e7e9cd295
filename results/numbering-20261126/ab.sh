#!/bin/bash
# The leaf rows by degree (commit d020fcc) against its parent (ddb98d3): both commits checked out side by side,
# the same solves run by each in turn, 2 rounds. Usage: ab.sh [OUT]
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
tmp=$(mktemp -d)
for c in ddb98d3 d020fcc; do git worktree add -f -q "$tmp/$c" $c; done
out=${1:-results/numbering-20261126/ab.txt}
: > "$out"
for k in 1 2; do
  for case in "free_surface random" "dmda2d random" "lognormal random" "fem_tri natural" "fem_tet natural" \
              "dmda2d natural"; do
    for c in ddb98d3 d020fcc; do
      .venv/bin/python results/numbering-20261126/solve.py "$tmp/$c" $case | tee -a "$out"
    done
  done
done
for c in ddb98d3 d020fcc; do git worktree remove --force "$tmp/$c"; done
