#!/bin/bash
# The CUDA-Graph fast path on a lent GPU (2026-11-26, through the device tool, from the repository root; the pyamg
# 5.4.1 cp312 wheel carried in .whl/, see results/bench-20261126gpu/run.sh). Code of ff06717: the run of
# results/bench-20261126gpu3 (9017dc7) after the foreign-operator changes since (leaf order by degree, sizing).
set -o pipefail
export PYTHONUNBUFFERED=1
python3 -m pip install --no-deps --no-index -q .whl/pyamg-*.whl
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader | tee "${OUT:-.}/gpu.txt"
python3 -c "import torch; print('torch', torch.__version__)" | tee -a "${OUT:-.}/gpu.txt"
python3 -m pytest -q -p no:cacheprovider tests/test_fastpath.py 2>&1 | tee "${OUT:-.}/pytest.log" | tail -3
python3 -m petsc_htp.fastpath --n 16384 65536 262144 --frames 3 --device cuda \
    --out "${OUT:-.}/fastpath_gpu.jsonl" > "${OUT:-.}/fastpath_gpu.log" 2>&1
grep -v "^ " "${OUT:-.}/fastpath_gpu.log" | tail -25
