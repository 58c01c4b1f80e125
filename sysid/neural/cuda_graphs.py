"""CUDA graphs of the simulation-error training step and of the hold-out free run (NVIDIA GPUs only).

Why: one step of ``ss-encoder`` is a T-step roll-out of 64-unit networks on a batch of sections — about a thousand
kernels of a few microseconds each, forward and backward — so an eager step on a GPU waits on the CPU that
launches them (measured on an H200: 1.6–2.9× slower than one CPU thread, docs/identifiers.md "GPU"). A CUDA graph
records the kernels of one step once and replays them with one launch (PyTorch's "whole-network capture",
``torch.cuda.CUDAGraph``): the arithmetic is the eager step's, so the model is the same to float rounding.

- :class:`GraphedStep` — gather of the sections at indices copied into a static buffer, forward, loss, backward,
  gradient clipping and the Adam step (``capturable=True``, the step size a tensor so that a schedule changes it
  between replays). Only full batches replay; a last, shorter batch runs eagerly with the same optimiser.
- :class:`GraphedRollout` — the free run of one hold-out record and its sum of squared errors, replayed after
  each epoch on the weights the optimiser has updated in place.

Capture needs warm-up first (lazy initialisation of cuBLAS, the autograd engine and Adam's moments): the first
full batches of the first epoch are the warm-up, taken eagerly on a side stream as real steps.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch

__all__ = ["GraphedStep", "GraphedRollout", "WARMUP_STEPS"]

WARMUP_STEPS = 3  # eager steps on a side stream before the capture (PyTorch's documented pattern)

Batch = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]


def _loss(model: torch.nn.Module, batch: Batch, k: torch.Tensor) -> torch.Tensor:
    ypast, upast, useq, target = batch(k)
    d = model(ypast, upast, useq) - target
    return (d * d).mean()


class GraphedStep:
    """One Adam step on a full batch of ``size`` sections, captured as a CUDA graph after ``WARMUP_STEPS``
    eager steps. Call it with the section starts of a batch; it returns the batch loss (a device tensor,
    overwritten by the next call). ``opt`` must be a ``capturable`` Adam with a tensor step size."""

    def __init__(self, model: torch.nn.Module, opt: torch.optim.Optimizer, batch: Batch, size: int, clip: float):
        self.model, self.opt, self.batch, self.size, self.clip = model, opt, batch, int(size), float(clip)
        self.graph: torch.cuda.CUDAGraph | None = None
        self.static_k: torch.Tensor | None = None
        self.loss: torch.Tensor | None = None
        self.warm = 0
        self._side = torch.cuda.Stream()

    def _eager(self, k: torch.Tensor) -> torch.Tensor:
        self.opt.zero_grad(set_to_none=True)
        loss = _loss(self.model, self.batch, k)
        loss.backward()
        if self.clip:
            torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.clip)
        self.opt.step()
        return loss.detach()

    def _capture(self, k: torch.Tensor) -> None:
        self.static_k = k.clone()
        self.opt.zero_grad(set_to_none=True)  # gradients then live in the graph's memory, rewritten each replay
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            loss = _loss(self.model, self.batch, self.static_k)
            loss.backward()
            if self.clip:
                torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.clip)
            self.opt.step()
        self.graph, self.loss = graph, loss.detach()

    def __call__(self, k: torch.Tensor) -> torch.Tensor:
        if k.numel() != self.size:
            return self._eager(k)
        if self.warm < WARMUP_STEPS:
            self._side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(self._side):
                loss = self._eager(k)
            torch.cuda.current_stream().wait_stream(self._side)
            self.warm += 1
            return loss
        if self.graph is None:
            self._capture(k)  # recorded, not run: this batch's step is the first replay
        assert self.graph is not None and self.static_k is not None and self.loss is not None
        self.static_k.copy_(k)
        self.graph.replay()
        return self.loss


class GraphedRollout:
    """Free run of one hold-out record ``(u (N, nu), y (N, ny))`` from its first ``lag`` samples, captured once and
    replayed on the current weights; :meth:`sse` returns (sum of squared errors, number of terms) in normalised
    units (``inf`` when non-finite), as :func:`sysid.neural.training.validation_rmse` sums them."""

    def __init__(
        self, model: torch.nn.Module, u: np.ndarray, y: np.ndarray, lag: int, dtype: torch.dtype = torch.float32
    ):
        dev = next(model.parameters()).device
        self.ut = torch.as_tensor(u, dtype=dtype, device=dev)[None]
        self.yt = torch.as_tensor(y, dtype=dtype, device=dev)[None]
        self.model, self.lag = model, int(lag)
        self.n = int(self.yt[:, self.lag :].numel())
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side), torch.no_grad():
            self._sum()  # warm-up outside the capture
        torch.cuda.current_stream().wait_stream(side)
        self.graph = torch.cuda.CUDAGraph()
        with torch.no_grad(), torch.cuda.graph(self.graph):
            self.static_sse = self._sum()

    def _sum(self) -> torch.Tensor:
        lag = self.lag
        yh = self.model(self.yt[:, :lag], self.ut[:, :lag], self.ut[:, lag:])
        d = (yh - self.yt[:, lag:]).double()
        return (d * d).sum()

    def sse(self) -> tuple[float, int]:
        self.graph.replay()
        v = float(self.static_sse.item())
        return (v if math.isfinite(v) else math.inf), self.n
