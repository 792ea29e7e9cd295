#!/bin/bash
# The CUDA-Graph fast path on a lent GPU (2026-11-26, through the device tool, from the repository root; the pyamg
# 5.4.1 cp312 wheel carried in .whl/, see results/bench-20261126gpu/run.sh). Code of 0546b7d: the dense coarse
# operator's limit follows the GPU's free memory (8 192 rows before), so the two-level rows at 262 144 run.
set -o pipefail
export PYTHONUNBUFFERED=1
python3 -m pip install --no-deps --no-index -q .whl/pyamg-*.whl
python3 -m pytest -q -p no:cacheprovider tests/test_fastpath.py 2>&1 | tee "${OUT:-.}/pytest.log"
python3 -m petsc_htp.fastpath --n 16384 65536 262144 --frames 3 --device cuda \
    --out "${OUT:-.}/fastpath_gpu.jsonl" > "${OUT:-.}/fastpath_gpu.log" 2>&1
grep -v "^ " "${OUT:-.}/fastpath_gpu.log" | tail -25
