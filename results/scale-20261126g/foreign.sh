#!/bin/bash
# The same A/B as run.sh (Chebyshev(2) against (3) on each level of the 2-D coarse V-cycles) on two foreign-study
# matrices at 1M rows on 2 ranks, where the coarse operator (about 88 000 rows) takes the V-cycles; interleaved.
# Usage: foreign.sh [OUT]; prints "case smoothing: iterations setup-ms solve-ms true-relres" per run.
cd "$(dirname "$0")/../.."
. .venv/bin/activate
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
H="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
out=${1:-results/scale-20261126g}
mkdir -p $out
for k in 1 2 3; do
  for case in lognormal free_surface; do
    for cheb in 2 3; do
      f=$out/${case}_1M_ranks2_cheb${cheb}_run$k.log
      mpiexec -n 2 python examples/matrix_file.py -case $case -n 1048576 $H -htp_cs_mg_levels_ksp_max_it $cheb > $f 2>&1
      echo "$case cheb$cheb: $(grep -E '^iterations|^setup ms|^solve ms|^true relative' $f | awk '{print $NF}' | tr '\n' ' ')"
    done
  done
done
