#!/bin/sh
# Diagonally dominant rows above the whole factors' sizes under Richardson, Chebyshev and CGS (2026-11-29, this 2-core
# AMD EPYC, one thread): HTPPC as it comes (ICC(0) kept), its V-cycles (-htp_variant multilevel -htp_direct_max 0,
# about what these KSPs took from 5222933 to 5de9276) and PETSc's own ICC(0), in turn, twice. From the repository root:
#   sh results/kspsweep-20261129/dominant.sh > results/kspsweep-20261129/dominant.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
for r in 1 2; do
  for k in richardson chebyshev cgs; do
    for o in "" "-htp_variant multilevel -htp_direct_max 0" "-pc_type icc"; do
      printf "[%s] " "$o"; PETSC_OPTIONS="$o" $P results/kspsweep-20261129/dominant.py $k 2.0 2>&1 | tail -1
    done
  done
done
