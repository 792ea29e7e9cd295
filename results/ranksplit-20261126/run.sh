#!/bin/bash
# How the rows' split over the ranks shows in -ksp_view (petsc_htp/ranksplit.py) and what it costs: foreign-study
# matrices handed over in their own row order (the P1 meshes number their nodes at random; the DMDA-style matrix in
# grid order, split in strips), HTPPC as it comes and the tuned GAMG, 1 and 2 ranks. Usage: run.sh [OUT].
cd "$(dirname "$0")/../.."
. .venv/bin/activate
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
H="-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
out=${1:-results/ranksplit-20261126}
mkdir -p $out
for case in dmda2d fem_tri fem_tet; do
  for r in 1 2; do
    f=$out/${case}_ranks${r}.log
    mpiexec -n $r python examples/matrix_file.py -case $case -n 65536 $H -ksp_view > $f 2>&1
    g=$out/${case}_ranks${r}_gamg.log
    mpiexec -n $r python examples/matrix_file.py -case $case -n 65536 -options_file options/cg_gamg.opts > $g 2>&1
    echo "$case $r ranks: HTPPC $(grep -E '^iterations' $f) GAMG $(grep -E '^iterations' $g)" \
         "$(grep -o 'ranks: [0-9]*; [0-9.]*% of the off-diagonal couplings' $f) ($(grep -c WARNING $f) warning(s))"
  done
done
