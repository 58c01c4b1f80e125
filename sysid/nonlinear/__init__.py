"""Nonlinear models grown from a linear one: the polynomial nonlinear state-space model started from the BLA and
a subspace fit (``pnlss``), and the Wiener–Hammerstein model from the best split of the BLA's poles and zeros
(``wh-bla``), each refined on simulation error with the exact Jacobian of its simulation.

May import: :mod:`sysid.errors`, :mod:`sysid.config`, :mod:`sysid.data`, :mod:`sysid.evaluation`, :mod:`sysid.base`,
:mod:`sysid.linear`.
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.nonlinear.pnlss import PNLSS
    from sysid.nonlinear.wiener_hammerstein import WienerHammerstein

__getattr__, __dir__, __all__ = attach(__name__, __file__)
