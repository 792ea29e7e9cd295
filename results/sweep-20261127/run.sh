#!/bin/sh
# The sweep's "now" files, one after the other (the "*_before.txt" files: the same commands with PYTHONPATH naming
# a worktree of bf5275c, where tests/bad_input_cases.py was copied in). From the repository root:
#     sh results/sweep-20261127/run.sh
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
D=results/sweep-20261127
PY=${PYTHON:-.venv/bin/python}
quiet() { grep -v yaksa; }
{ $PY $D/penalty_jump.py; mpiexec -n 2 $PY $D/penalty_jump.py 200; } 2>&1 | quiet > $D/penalty.txt
{ $PY $D/shortcuts.py; mpiexec -n 2 $PY $D/shortcuts.py; } 2>&1 | quiet > $D/shortcuts.txt
$PY $D/turns.py > $D/turns.txt
for pair in loose:loose_coarse_cycles rows_last:penalty_rows_last; do
  out=$D/${pair%%:*}.txt; case=${pair#*:}
  echo "# now ($(git rev-parse --short HEAD)): mpiexec -n N python tests/bad_input_cases.py DIR $case" > $out
  for n in 1 2 3; do mpiexec -n $n $PY tests/bad_input_cases.py /tmp $case 2>&1 | quiet | grep "rank 0" >> $out; done
done
