#!/bin/sh
# KSPs other than CG around HTPPC on the foreign study's larger matrices, and Richardson where the two-level method
# had diverged (2026-11-29, this 2-core AMD EPYC, one thread per rank; one process per solve). Each line: case, rows,
# KSP, iterations, PETSc's reason, true relative residual; "[options]" where PETSC_OPTIONS set some.
# From the repository root:  sh results/kspsweep-20261129/sweep.sh > results/kspsweep-20261129/sweep.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-.venv/bin/python}
ONE=results/kspsweep-20261129/one.py
for c in "dmda2d 40000" "dmda3d 40000" "fem_tri 65536" "fem_tet 30000"; do
  for k in gmres fgmres minres bcgs pipecg gcr richardson tfqmr cgs bicg chebyshev; do
    timeout 300 $P $ONE ${c% *} $k ${c#* } 2>&1 | tail -1
  done
done
echo "# Richardson: as it comes, then the two-level method kept (-htp_variant twolevel, the method before)"
for c in "fem_tet 12000" "fem_tet 30000" "heat_tet 12000" "heat_tet 30000" "fem_hex 27000" "dmda2d 16384" \
         "fem_tri 16384" "aniso_e0.01_a30 16384" "lognormal 16384" "neumann 16384"; do
  for o in "" "-htp_variant twolevel"; do
    printf "[%s] " "$o"; PETSC_OPTIONS="$o" timeout 300 $P $ONE ${c% *} richardson ${c#* } 2>&1 | tail -1
  done
done
for o in "-pc_type gamg" "-pc_type bjacobi" "-htp_variant twolevel -ksp_richardson_self_scale"; do
  printf "[%s] " "$o"; PETSC_OPTIONS="$o" timeout 300 $P $ONE fem_tet richardson 30000 2>&1 | tail -1
done
echo "# Richardson on 2 ranks, rows split in the case's own (random) order: examples/matrix_file.py"
for n in 12000 64000; do
  for o in "" "-htp_variant twolevel"; do
    printf "fem_tet %s 2 ranks [%s]: " $n "$o"
    timeout 600 mpiexec -n 2 $P examples/matrix_file.py -case fem_tet -n $n -ksp_type richardson -ksp_max_it 10000 \
      -ksp_norm_type unpreconditioned -ksp_rtol 1e-8 -pc_type python -pc_python_type petsc_htp.HTPPC $o \
      | grep -E "^iterations|^converged reason|^setup ms|^true relative" | tr '\n' ' '
    echo
  done
done
echo "# Chebyshev and CGS on ICC(0)'s small matrices: HTPPC as it comes, then PETSc's ICC(0)"
for c in "pyamg_bar chebyshev" "pyamg_bar cgs" "fem_tri chebyshev 8000"; do
  for o in "" "-pc_type icc"; do
    printf "[%s] " "$o"; PETSC_OPTIONS="$o" timeout 300 $P $ONE $c 2>&1 | grep -E "^(pyamg|fem)"
  done
done
