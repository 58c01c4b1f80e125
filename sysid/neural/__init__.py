"""Neural identifiers (PyTorch): the dissertation's NARX-MLP (one-step and simulation-error training) and a
recurrent state-space models. Structure sweeps, which tune any identifier, are in :mod:`sysid.search`.

Import the classes from their modules (``sysid.neural.narx_mlp``, ``sysid.neural.rnn``); importing this
package does not import torch.
"""
