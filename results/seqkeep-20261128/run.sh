#!/bin/sh
# Sequence frames of the plain DMDA program (examples/dmda_poisson.py: new inclusions every frame, so the couplings
# move away from the finest leaves) at commits OLD and NEW, run in turn REPS times: each run's median frame set-up,
# solve and set-up + solve ms and the frames' iterations (frame 0, the single solve, left out). 2026-11-28, this
# 2-core AMD EPYC, one thread. From the repository root:
#   sh results/seqkeep-20261128/run.sh OLD NEW N FRAMES REPS > results/seqkeep-20261128/N.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
OLD=$1; NEW=$2; N=${3:-256}; FRAMES=${4:-8}; REPS=${5:-5}
COMMITS="$OLD $NEW"
. results/abtrees.sh
for r in $(seq $REPS); do
  for c in $OLD $NEW; do
    $P "$TREES/$c/examples/dmda_poisson.py" -n $N -warmup -frames $FRAMES $HTP > "$TREES/out" 2>&1
    printf "%s run %s: " $c $r
    $P -c 'import re, statistics as st, sys
t = open(sys.argv[1]).read()
f = [(float(a), float(b), int(c)) for c, a, b in re.findall(r"^frame \d+: iterations (\d+), .*setup ms ([\d.]+), solve ms ([\d.]+)", t, re.M)]
print(f"median setup {st.median(a for a, _, _ in f):.1f} ms, solve {st.median(b for _, b, _ in f):.1f} ms, "
      f"setup + solve {st.median(a + b for a, b, _ in f):.1f} ms, iterations {[c for _, _, c in f]}")' "$TREES/out"
  done
done
trees_remove
