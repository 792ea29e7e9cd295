#!/bin/bash
# The 2-D coarse V-cycles' smoothing: Chebyshev(2) on each level (the default since this folder) against Chebyshev(3)
# (-htp_cs_mg_levels_ksp_max_it 3, the default before), interleaved, HTPPC as it comes, one thread per rank. Two GAMG
# V-cycles serve the coarse operator above 16 384 coarse rows on several ranks and above 131 072 on one.
# Usage: run.sh [OUT] [PART]: PART dmda (default; summary.txt) runs the DMDA program and prints "N ranks smoothing:
# iterations setup-ms solve-ms"; PART foreign (foreign_summary.txt) two foreign-study matrices at 1M rows on 2 ranks
# (coarse operators of about 88 000 rows), printing "case smoothing: iterations setup-ms solve-ms true-relres".
cd "$(dirname "$0")/../.."
. .venv/bin/activate
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
H="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
out=${1:-results/scale-20261126g}
mkdir -p $out
run() {  # n ranks reps
  for k in $(seq $3); do
    for cheb in 2 3; do
      f=$out/dmda2d_$1_ranks$2_cheb${cheb}_run$k.log
      mpiexec -n $2 python examples/dmda_poisson.py -dim 2 -n $1 -warmup $H -htp_cs_mg_levels_ksp_max_it $cheb > $f 2>&1
      echo "$1 $2 cheb$cheb: $(grep -E '^iterations|^setup ms|^solve ms' $f | awk '{print $NF}' | tr '\n' ' ')"
    done
  done
}
foreign() {  # reps
  for k in $(seq $1); do
    for case in lognormal free_surface; do
      for cheb in 2 3; do
        f=$out/${case}_1M_ranks2_cheb${cheb}_run$k.log
        mpiexec -n 2 python examples/matrix_file.py -case $case -n 1048576 $H -htp_cs_mg_levels_ksp_max_it $cheb > $f 2>&1
        echo "$case cheb$cheb: $(grep -E '^iterations|^setup ms|^solve ms|^true relative' $f | awk '{print $NF}' | tr '\n' ' ')"
      done
    done
  done
}
if [ "${2:-dmda}" = foreign ]; then
  foreign 3
else
  run 512 2 4
  run 1024 2 4
  run 2048 2 2
  run 2048 1 1
fi
