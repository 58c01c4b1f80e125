"""Device and thread selection for the neural identifiers.

``device="auto"`` picks CUDA when ``torch.cuda.is_available()`` and the CPU otherwise; ``"cpu"`` and
``"cuda"`` (or ``"cuda:N"``) force one. The environment variable ``PIEZOTWIN_DEVICE`` overrides ``auto``.
Training data, parameters and optimiser state all live on the chosen device; predictions are computed on
the CPU in float64 from the trained weights, so a model trained on a GPU predicts the same on any machine.

Threads: the networks of the dissertation are small (a 4 × 25 MLP has 2501 weights), so one CPU thread per
process is fastest: extra threads only add synchronisation per tiny matrix product (docs/identifiers.md).
``PIEZOTWIN_TORCH_THREADS`` overrides the choice.
"""

from __future__ import annotations

import os

import torch

from sysid.errors import ConfigError

__all__ = ["select_device", "configure_threads", "TRAIN_DTYPES", "train_dtype"]

# Floating-point precision of training (`dtype` option of the neural identifiers). float32 is the fast default.
# torch's kernels for AVX-512, AVX2 and generic CPUs round reductions and fused multiply-adds differently; in
# float32 that changes the trained weights in their last digits (quick Silverbox narx-mlp free-run RMSE 5.5152 vs
# 5.5154 mV, generic vs AVX2 kernels, seed 0). In float64 one-step training gave the same RMSE to 12 digits on both,
# the rnn to 8. Simulation-error training (narx-mlp-sim) amplifies even float64 rounding into a different model,
# as a different seed would (6.2 vs 7.8 mV; float32 10.5 vs 3.2 mV): only statistics over seeds are CPU-independent.
TRAIN_DTYPES = {"float32": torch.float32, "float64": torch.float64}


def select_device(device: str = "auto") -> torch.device:
    """Resolve ``"auto" | "cpu" | "cuda" | "cuda:N"`` to a :class:`torch.device`; refuse CUDA when absent."""
    name = str(device or "auto").strip().lower()
    if name == "auto":
        name = os.environ.get("PIEZOTWIN_DEVICE", "").strip().lower() or (
            "cuda" if torch.cuda.is_available() else "cpu"
        )
    if name == "cpu":
        return torch.device("cpu")
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ConfigError(f"device={device!r}: CUDA is not available on this machine (use device=cpu or auto)")
        try:
            dev = torch.device(name)
        except RuntimeError:
            raise ConfigError(f"device={device!r}: not a valid CUDA device name") from None
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ConfigError(f"device={device!r}: only {torch.cuda.device_count()} CUDA device(s) present")
        return dev
    raise ConfigError(f"device={device!r}: expected auto, cpu, cuda or cuda:N")


def configure_threads(n: int | None = None) -> int:
    """Set torch's intra-op threads (default 1, or ``PIEZOTWIN_TORCH_THREADS``); return the number set."""
    if n is None:
        n = int(os.environ.get("PIEZOTWIN_TORCH_THREADS", "1") or 1)
    n = max(1, int(n))
    if torch.get_num_threads() != n:
        torch.set_num_threads(n)
    return n


def train_dtype(name: str, what: str) -> torch.dtype:
    """The torch dtype of a ``dtype`` option (``float32`` or ``float64``); ConfigError otherwise."""
    if name not in TRAIN_DTYPES:
        raise ConfigError(f"{what}: dtype={name!r} not one of: {', '.join(TRAIN_DTYPES)}")
    return TRAIN_DTYPES[name]
