#!/bin/bash
# The CUDA-Graph fast path on a lent GPU (2026-11-28, through the device tool, from the repository root; code of the
# commit named in gpu.txt). A pyamg 5.4.1 cp312 wheel travels in .whl/ (carry: [".whl"]), fetched here with
# `pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp
#  --platform manylinux_2_28_x86_64 -d .whl pyamg==5.4.1`. The run of bench-20261126gpu4 (ff06717, in the git
# history) after the two-level and multilevel changes since.
set -o pipefail
export PYTHONUNBUFFERED=1
python3 -m pip install --no-deps --no-index -q .whl/pyamg-*.whl
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader | tee "${OUT:-.}/gpu.txt"
python3 -c "import torch; print('torch', torch.__version__)" | tee -a "${OUT:-.}/gpu.txt"
git rev-parse HEAD 2>/dev/null | tee -a "${OUT:-.}/gpu.txt"
python3 -m pytest -q -p no:cacheprovider tests/test_fastpath.py 2>&1 | tee "${OUT:-.}/pytest.log" | tail -3
python3 -m petsc_htp.fastpath --n 16384 65536 262144 --frames 3 --device cuda \
    --out "${OUT:-.}/fastpath_gpu.jsonl" > "${OUT:-.}/fastpath_gpu.log" 2>&1
grep -v "^ " "${OUT:-.}/fastpath_gpu.log" | tail -25
