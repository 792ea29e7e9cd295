#!/bin/sh
# The multilevel V-cycles' coarse size in 2-D (-htp_ml_coarse_max; 2026-11-28, this 2-core AMD EPYC, one thread).
# Run from the repository root. a/ and b/ were measured at commit cfb9c47, whose cg_htp had 1 000 rows (htp_cm1000
# here), and the /tmp copies of the options files below:
#   sh results/multilevel-20261128g/coarse.sh
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
D=results/multilevel-20261128g
$P -m petsc_htp.bench --studies foreign --methods $D/htp_cm1000.opts $D/htp_cm2000.opts $D/htp_cm3000.opts \
    $D/htp_cm5000.opts amgcl --foreign-scales 65536 1048576 --foreign-cases dmda2d free_surface lognormal neumann \
    --foreign-frames 1 --threads 1 --out $D/a --no-progress
$P -m petsc_htp.bench --studies foreign --methods $D/htp_cm1000.opts $D/htp_cm5000.opts $D/htp_cm10000.opts \
    $D/htp_cm20000.opts --foreign-scales 65536 1048576 --foreign-cases dmda2d free_surface lognormal neumann \
    --foreign-frames 1 --threads 1 --out $D/b --no-progress
# 3-D (-htp_variant multilevel, the 64^3 DMDA program, one solve after a warm-up), 1 000 against 5 000 rows (3d.txt
# after commit 5e648f3):
for cm in 1000 5000; do
  echo "coarse_max $cm"
  $P examples/dmda_poisson.py -dim 3 -n 64 -warmup -ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned \
      -pc_type python -pc_python_type petsc_htp.HTPPC -htp_variant multilevel -htp_ml_coarse_max $cm
done > $D/3d.txt
