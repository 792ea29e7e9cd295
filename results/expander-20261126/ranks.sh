#!/bin/bash
# A graph that is no mesh on 1 and 2 ranks: run.py's scale-free graph at 60 000 and 200 000 rows and its mixed-sign
# random graph at 60 000 written to a file (write.py) and solved by examples/matrix_file.py with HTPPC as it comes and with its two-level method
# (-htp_direct_max 0), one thread per rank. Usage: ranks.sh [OUT]; prints "N graph ranks method: iterations setup
# solve".
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
out=${1:-results/expander-20261126/ranks.txt}
tmp=$(mktemp -d)
H="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
echo "# $(date +%F), commit $(git rev-parse --short HEAD); iterations, setup ms, solve ms" > "$out"
for graph in "60000 ba" "200000 ba" "60000 mixed"; do
  set -- $graph
  n=$1
  .venv/bin/python results/expander-20261126/write.py $graph "$tmp/ba.petsc"
  for r in 1 2; do
    for m in default two-level; do
      opts=$H; [ $m = two-level ] && opts="$H -htp_direct_max 0"
      line=$(mpiexec -n $r .venv/bin/python examples/matrix_file.py -f "$tmp/ba.petsc" $opts \
             | grep -E '^iterations|^setup ms|^solve ms' | awk '{print $NF}' | tr '\n' ' ')
      echo "$n $2 $r $m: $line" | tee -a "$out"
    done
  done
done
rm -rf "$tmp"
