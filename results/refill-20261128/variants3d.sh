#!/bin/sh
# The foreign study's 3-D cases with HTPPC as it comes (the two-level method), an exact coarse LU, and the multilevel
# V-cycles: frame 0 a fresh KSP, then FRAMES more with new values on the same KSP (results/bound-20261128/frames.py;
# 2026-11-28, this 2-core AMD EPYC, one thread). From the repository root:
#   sh results/refill-20261128/variants3d.sh > results/refill-20261128/variants3d.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
for opts in "" "-htp_coarse_solver lu" "-htp_variant multilevel"; do
  printf "fem_tet 65536 [%s]: " "$opts"; $P results/bound-20261128/frames.py 65536 2 fem_tet $opts | sed 's/^[^:]*: //'
done
for n in 32768 64000 125000; do
  for opts in "" "-htp_variant multilevel"; do
    printf "dmda3d %s [%s]: " $n "$opts"; $P results/bound-20261128/frames.py $n 3 dmda3d $opts | sed 's/^[^:]*: //'
  done
done
