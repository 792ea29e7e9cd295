"""Device resolution, host sync, kernel timing and CUDA Graph capture for the fast path."""
from __future__ import annotations

import time

import torch

from ..paper.inference import resolve_device


def device_of(device) -> torch.device:
    """Resolve 'auto'/'cpu'/'cuda[:i]' (or a torch.device) to a device with an explicit CUDA index."""
    dev = resolve_device(device) if isinstance(device, str) else torch.device(device)
    if dev.type == "cuda" and dev.index is None:
        dev = torch.device("cuda", torch.cuda.current_device())
    return dev



def sync(device: torch.device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed(fn, device: torch.device):
    """Run ``fn()``; return (its result, milliseconds) from CUDA events on GPU, perf_counter on CPU."""
    if device.type == "cuda":
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
        out = fn()
        end.record()
        end.synchronize()
        return out, start.elapsed_time(end)
    t0 = time.perf_counter()
    out = fn()
    return out, 1e3 * (time.perf_counter() - t0)


def capture(fn, warmup: int = 2):
    """Warm ``fn`` up on a side stream, then capture it; return (CUDAGraph, fn's output)."""
    stream = torch.cuda.Stream()
    stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(stream):
        for _ in range(warmup):
            fn()
    torch.cuda.current_stream().wait_stream(stream)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        out = fn()
    return graph, out
