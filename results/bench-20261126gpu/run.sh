#!/bin/bash
# The CUDA-Graph fast path on a lent GPU (2026-11-26, NVIDIA H100 80GB HBM3, torch 2.11.0+cu130, Python 3.12, code of
# c410253), run through the device tool from the repository root with a pyamg 5.4.1 cp312 wheel carried in .whl/
# (`pip download pyamg --python-version 3.12 --only-binary=:all: --platform manylinux_2_28_x86_64 --no-deps -d .whl/`):
python3 -m pip install --no-deps --no-index -q .whl/pyamg-*.whl
python3 -m pytest -q -p no:cacheprovider tests/test_fastpath.py          # 41 passed, the 8 CUDA tests included
python3 -m petsc_htp.fastpath --n 16384 65536 262144 --frames 3 --device cuda \
    --out results/bench-20261126gpu/fastpath_gpu.jsonl > results/bench-20261126gpu/fastpath_gpu.log 2>&1
