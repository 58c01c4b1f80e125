"""Neural identifiers (PyTorch): the dissertation's NARX-MLP (one-step and simulation-error training) and the
sequence models trained on simulation error — a recurrent state-space model, the encoder state-space model
(SUBNET) and a block-oriented Wiener–Hammerstein network — with one training loop for all of them.

Importing this package does not import torch; the first use of a class does.
May import: :mod:`sysid.errors`, :mod:`sysid._blas`, :mod:`sysid.progress`, :mod:`sysid.data`,
:mod:`sysid.evaluation`, :mod:`sysid.base`.
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.neural.narx_mlp import NARXMLP, NARXMLPSim
    from sysid.neural.rnn import RNNStateSpace
    from sysid.neural.ss_encoder import SSEncoder
    from sysid.neural.wh_net import WHNet

__getattr__, __dir__, __all__ = attach(__name__, __file__)
