"""A standalone float32 PCG on torch alone, timed like the paper (no PETSc needed).

The whole inner loop (preconditioner apply, CSR SpMV, SAXPYs, float64 dot
reductions) runs on preallocated device buffers; on CUDA, ``check_every``
unrolled iterations are captured once per (N, method) as one CUDA Graph and
replayed, with one host sync per replay to test convergence. On CPU the same
step function runs eagerly.

    pc = make_preconditioner("jacobi", A)
    res = GraphPCG(A, pc).solve(b)           # res.x, res.iterations, res.reason

``python -m petsc_htp.fastpath --n 1024 --out results.jsonl`` benchmarks every method.
"""
from .inference_graph import InferenceGraph, capture_inference
from .preconditioners import (
    METHODS,
    BlockJacobi,
    HTPPreconditioner,
    Jacobi,
    Preconditioner,
    apply_microbench,
    make_preconditioner,
)
from .run import main, run_fastpath, write_jsonl
from .solver import REASONS, FastResult, GraphPCG

__all__ = [
    "METHODS",
    "REASONS",
    "make_preconditioner",
    "apply_microbench",
    "Preconditioner",
    "Jacobi",
    "BlockJacobi",
    "HTPPreconditioner",
    "FastResult",
    "GraphPCG",
    "InferenceGraph",
    "capture_inference",
    "run_fastpath",
    "write_jsonl",
    "main",
]
