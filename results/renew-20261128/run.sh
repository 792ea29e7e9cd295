#!/bin/sh
# Sequence frames of the plain DMDA program (examples/dmda_poisson.py: new inclusions every frame, so the couplings
# move away from the leaves and the multilevel hierarchy is built anew each frame) at commit 68b2767 (a new analysis
# each such frame: the whole-matrix choice and the null components again) and at dffb055 (the hierarchy built anew in
# the numeric step, the analysis kept), run in turn REPS times: -log_view's HTPSetup and HTPChoice (count, total s)
# and each run's median frame set-up and solve ms. 2026-11-28, this 2-core AMD EPYC, one thread. From the repository
# root:  sh results/renew-20261128/run.sh N FRAMES REPS > results/renew-20261128/N.txt
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
P=${PYTHON:-$(pwd)/.venv/bin/python}
N=${1:-256}; FRAMES=${2:-8}; REPS=${3:-5}
COMMITS="68b2767 dffb055"
. results/abtrees.sh
for r in $(seq $REPS); do
  for c in 68b2767 dffb055; do
    $P "$TREES/$c/examples/dmda_poisson.py" -n $N -warmup -frames $FRAMES $HTP -log_view > "$TREES/out" 2>&1
    printf "%s run %s: " $c $r
    $P -c 'import re, statistics as st, sys
t = open(sys.argv[1]).read()
f = [(float(a), float(b), c) for c, a, b in re.findall(r"^frame \d+: iterations (\d+), .*setup ms ([\d.]+), solve ms ([\d.]+)", t, re.M)]
e = "; ".join(f"{m[0]} {m[1]} calls {float(m[2]):.3f} s" for m in re.findall(r"^(HTPSetup|HTPChoice) +(\d+) [\d.]+ ([\d.e+-]+)", t, re.M))
print(f"{e}; frames: median setup {st.median(a for a, _, _ in f):.1f} ms, solve {st.median(b for _, b, _ in f):.1f} ms, iterations {[int(c) for _, _, c in f]}")' "$TREES/out"
  done
done
trees_remove
