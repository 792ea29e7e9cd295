#!/bin/sh
# The plain DMDA program (examples/dmda_poisson.py, one solve after a warm-up) at 512^2 and 1024^2 on 1 and 2 ranks,
# HTPPC as it comes (the coarsest level by its banded Cholesky factor), five runs each in turn (2026-11-28, this 2-core AMD EPYC,
# commit efcd615+). From the repository root:
#   sh results/coarse-20261128/ranks.sh > results/coarse-20261128/ranks.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
HTP="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
for n in 512 1024; do
  for run in 1 2 3 4 5; do
    for r in 1 2; do
      printf "n=%s ranks=%s run=%s: " $n $r $run
      mpiexec -n $r $P examples/dmda_poisson.py -n $n -warmup $HTP | grep -E "^iterations|^setup ms|^solve ms" | tr '\n' ' '
      echo
    done
  done
done
