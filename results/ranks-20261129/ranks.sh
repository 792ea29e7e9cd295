#!/bin/sh
# A second rank against one, with PETSc's GAMG beside HTPPC as the reference of what this machine's second core gives
# (2026-11-29, this 2-core AMD EPYC, one thread per rank): the plain 2-D DMDA program (examples/dmda_poisson.py, one
# solve after a warm-up) at sides 512 and 1024 on 1 and 2 ranks, HTPPC as it comes, GAMG with the project's tuned
# options file and with PETSc's defaults, methods and rank counts in turn, REPS times.
# From the repository root:  sh results/ranks-20261129/ranks.sh REPS > results/ranks-20261129/ranks.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
REPS=${1:-3}
HTP="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
GAMG_DEFAULT="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type gamg"
for r in $(seq $REPS); do
  for n in 512 1024; do
    for m in htp gamg gamg_default; do
      for ranks in 1 2; do
        case $m in
          htp) opts=$HTP ;;
          gamg) opts="-options_file options/cg_gamg.opts" ;;
          gamg_default) opts=$GAMG_DEFAULT ;;
        esac
        printf "n=%s %s ranks=%s run=%s: " $n $m $ranks $r
        mpiexec -n $ranks $P examples/dmda_poisson.py -n $n -warmup $opts | grep -E "^iterations|^setup ms|^solve ms" | tr '\n' ' '
        echo
      done
    done
  done
done
