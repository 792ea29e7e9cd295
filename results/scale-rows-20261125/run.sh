#!/bin/bash
# Row-scaled operators: the DMDA program's matrix as D A D (D in 1e-2 .. 1e2 per row) against A itself, with
# and without coefficient jumps, one thread, one solve after a warm-up; HTPPC as it comes, GAMG tuned and as
# PETSc sets it up, ICC(0). Usage: results/scale-rows-20261125/run.sh [PYTHON_ROOT] (another checkout to compare).
cd "$(dirname "$0")/../.."
. .venv/bin/activate
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
root=${1:-.}
H="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
for contrast in 1 1000; do
  for scale in 0 2; do
    for m in htppc gamg gamgdef icc; do
      case $m in htppc) o=$H;; gamg) o="-options_file options/cg_gamg.opts";;
                 gamgdef) o="-options_file options/cg_gamg_default.opts";; icc) o="-options_file options/cg_icc.opts";; esac
      [ "$root" != . ] && [ $m != htppc ] && continue
      out=$(python $root/examples/dmda_poisson.py -n 256 -warmup -contrast $contrast -scale_rows $scale $o)
      echo "contrast $contrast scale $scale $m: $(echo "$out" | grep -E '^iterations|^setup ms|^solve ms|^true' | awk '{print $NF}' | tr '\n' ' ')"
    done
  done
done
