#!/bin/bash
# 2-D DMDA program on 1 and 2 ranks after the analysis speed-ups and with the coarse LU up to 400 000 rows on one
# rank (2026-11-25, commit 8016834); at 2048^2 on one rank also the former coarse V-cycle (-htp_coarse_solver gamg).
cd "$(dirname "$0")/../.."
out=results/scale-20261125g
results/scale-20261124b/run.sh $out "2 512 3" "2 1024 2" "2 2048 1"
. .venv/bin/activate
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
f=$out/dmda2d_2048_htppc-vcycle_ranks1_run1.log
cmd="python examples/dmda_poisson.py -dim 2 -n 2048 -warmup -ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC -htp_coarse_solver gamg"
echo "mpiexec -n 1 $cmd" > $f
/usr/bin/time -v mpiexec -n 1 $cmd >> $f 2>&1
echo "2-D 2048 1 htppc-vcycle 1: $(grep -E '^iterations|^setup ms|^solve ms' $f | tr '\n' ' ') rss $(grep 'Maximum resident' $f | awk '{print $6}')"
