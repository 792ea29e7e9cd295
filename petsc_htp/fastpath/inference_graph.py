"""The HTP network forward replayed as a CUDA Graph on static inputs (eager on CPU)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch

from ..paper.features import input_values
from .timing import capture, timed


class InferenceGraph:
    """The HTP network forward for one N on static inputs: a CUDA Graph on GPU, eager otherwise.

    ``scale`` is kept as a device tensor so a replay reads each frame's value.
    If capture fails, the forward stays eager and ``error`` says why.
    """

    def __init__(self, htp, A, coords=None, density=None):
        self.htp, self.device = htp, htp.device
        self.part = htp.net.cfg.partition(A.shape[0])
        self.analysis = htp.analyse(A, coords)
        self.perm = self.analysis.perm
        self.inp = self._features(A, density)
        self.graph, self.error = None, None
        self.inference_ms = None
        with torch.no_grad():
            self.out = htp.net(self.inp, self.part)
            if self.device.type == "cuda":
                try:
                    self.graph, self.out = capture(lambda: htp.net(self.inp, self.part))
                except Exception as exc:  # any op the capture rejects: stay eager
                    self.error = f"{type(exc).__name__}: {exc}"

    @property
    def graphed(self) -> bool:
        """True when the forward replays as a CUDA Graph."""
        return self.graph is not None

    def _features(self, A, density):
        inp = input_values(self.analysis.structure, self.analysis.permuted(sp.csr_matrix(A)),
                           None if density is None else np.asarray(density)[self.perm])
        inp.scale = torch.tensor(inp.scale, dtype=torch.float32)
        return inp.to(self.device)

    @torch.no_grad()
    def __call__(self, A, density=None) -> torch.Tensor:
        """Refresh the inputs from ``A`` (same pattern and coordinates as captured); return the packed factors.

        The forward's milliseconds (features excluded) go to ``inference_ms``.
        """
        new = self._features(A, density)
        for name, value in vars(new).items():
            old = getattr(self.inp, name)
            if value.layout == torch.sparse_coo:
                if value._nnz() != old._nnz():
                    raise ValueError("the operator's sparsity pattern differs from the captured one")
                old._indices().copy_(value._indices())
                old._values().copy_(value._values())
            else:
                old.copy_(value)
        if self.graph is not None:
            _, self.inference_ms = timed(self.graph.replay, self.device)
        else:
            self.out, self.inference_ms = timed(lambda: self.htp.net(self.inp, self.part), self.device)
        return self.out


def capture_inference(htp, A, coords=None, density=None) -> InferenceGraph:
    """Capture the network forward for ``A``'s N (CUDA Graph on GPU, eager on CPU)."""
    return InferenceGraph(htp, A, coords, density)
