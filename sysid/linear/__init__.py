"""Linear models and the frequency domain: FIR, ARX/ARMAX, OE/BJ by the prediction-error method, subspace
(N4SID), the BLA and its OE-type model, an output-error model with an echo path; nonparametric FRFs, transfer
functions fitted to them, delay and order selection, and the models' uncertainty (dissertation §2.4–2.6).

The references every nonlinear model must beat (:data:`sysid.registry.LINEAR_IDENTIFIERS`).
May import: :mod:`sysid.errors`, :mod:`sysid.config`, :mod:`sysid.data`, :mod:`sysid.evaluation`,
:mod:`sysid.report`, :mod:`sysid.base`, :mod:`sysid.polynomial` (ARX/ARMAX are degree-1 polynomial models),
:mod:`sysid.registry` (by name).
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.linear.arx import ARMAX, ARX
    from sysid.linear.bla import BLA, best_linear_approximation, detect_nonlinearity
    from sysid.linear.bla_model import BLAModel
    from sysid.linear.echo_oe import EchoOE
    from sysid.linear.fir import FIR
    from sysid.linear.frf import FRF, excited_lines, frf_periodic, frf_welch
    from sysid.linear.order import delay_estimate, order_table, select_arx_orders, select_n4sid_order, select_oe_orders
    from sysid.linear.pem import BJ, OE
    from sysid.linear.subspace import N4SID
    from sysid.linear.tfest import TransferFunction
    from sysid.linear.uncertainty import monte_carlo_band, poles_with_std, tf_response_with_std

__getattr__, __dir__, __all__ = attach(__name__, __file__)
