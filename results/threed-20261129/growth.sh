#!/bin/sh
# The plain DMDA program in 3-D (examples/dmda_poisson.py -dim 3, a warm-up, frame 0, then 3 frames with the balls of
# the next seeds in the same Mat and KSP), HTPPC as it comes, at sides 32, 64 and 128 on one rank and 128 on two
# (2026-11-29, this 2-core AMD EPYC, one thread per rank). From the repository root:
#   sh results/threed-20261129/growth.sh > results/threed-20261129/growth.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
HTP="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
for run in "1 32" "1 64" "1 128" "2 128"; do
  echo "ranks ${run% *}, side ${run#* }:"
  /usr/bin/time -f "largest process's peak RSS: %M kB" mpiexec -n ${run% *} $P examples/dmda_poisson.py -dim 3 \
      -n ${run#* } -frames 3 -warmup $HTP 2>&1 | grep -E "^iterations|^setup ms|^solve ms|^frame|peak RSS"
done
