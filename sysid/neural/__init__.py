"""Neural identifiers (PyTorch): the dissertation's NARX-MLP (one-step and simulation-error training) and a
recurrent state-space model, plus structure sweeps (:mod:`sysid.neural.search`).

Import the classes from their modules (``sysid.neural.narx_mlp``, ``sysid.neural.rnn``); importing this
package does not import torch.
"""
