"""Black-box identification of (piezoelectric) systems; depends on nothing else of this project.

Filed by family, one sub-package each, lower ones never importing higher ones (``tests/test_layering.py``):

- :mod:`sysid.data` — the :class:`Record`, data and model files, atomic output;
- :mod:`sysid.signals` — excitation design and preprocessing;
- :mod:`sysid.evaluation` — metrics, residual correlation tests, evaluation of a model on records;
- :mod:`sysid.report` — figures, HTML pages, provenance, comparison of saved models;
- :mod:`sysid.polynomial` — polynomial NARX/NARMAX by FROLS; :mod:`sysid.linear` — FIR, ARX/ARMAX, OE/BJ, N4SID,
  FRF/BLA; :mod:`sysid.nonlinear` — PNLSS and Wiener–Hammerstein; :mod:`sysid.neural` — PyTorch models;
- :mod:`sysid.search` — structure sweeps on Optuna.

Beside them: the identifier interface (:mod:`sysid.base`), the registry of identifier ids (:mod:`sysid.registry`),
``--set`` parsing (:mod:`sysid.config`), identification as the CLI does it (:mod:`sysid.identify`), the
sample-by-sample stepper of FMUs (:mod:`sysid.stepper`), errors, BLAS threads and progress bars.

The public names below import from ``sysid`` directly, loaded on first use (``import sysid`` loads neither scipy
nor torch). Module paths of the flat layout before the families (``sysid.pem``, ``sysid.metrics``, ...) still
import, with a DeprecationWarning (:mod:`sysid._exports`).
"""

from typing import TYPE_CHECKING

from sysid._exports import attach, install_aliases
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, InputError

if TYPE_CHECKING:
    from sysid.base import Identifier, load_model
    from sysid.data.io import read_record, write_record
    from sysid.errors import ConfigError, DataError, InputError
    from sysid.evaluation.metrics import fit_percent, mse, nrmse, r2, rmse
    from sysid.evaluation.residuals import correlation_tests, residual_spectrum
    from sysid.linear.arx import ARMAX, ARX
    from sysid.linear.bla import best_linear_approximation, detect_nonlinearity
    from sysid.linear.bla_model import BLAModel
    from sysid.linear.echo_oe import EchoOE
    from sysid.linear.fir import FIR
    from sysid.linear.frf import frf_periodic, frf_welch
    from sysid.linear.order import delay_estimate
    from sysid.linear.pem import BJ, OE
    from sysid.linear.subspace import N4SID
    from sysid.neural.narx_mlp import NARXMLP, NARXMLPSim
    from sysid.neural.rnn import RNNStateSpace
    from sysid.neural.ss_encoder import SSEncoder
    from sysid.neural.wh_net import WHNet
    from sysid.nonlinear.pnlss import PNLSS
    from sysid.nonlinear.wiener_hammerstein import WienerHammerstein
    from sysid.polynomial.narmax import NARMAXPoly, NARXPoly
    from sysid.polynomial.polysim import NARXPolySim
    from sysid.registry import IDENTIFIERS, available_identifiers, get_identifier
    from sysid.search import parse_grid, run_sweep
    from sysid.signals.excitation import aprbs, chirp, crest_factor, multisine, sine, stepped_sine
    from sysid.signals.preprocess import (
        bandpass,
        decimate,
        detrend,
        fill_missing,
        hampel,
        moving_average,
        remove_offset,
        resample,
        segment,
    )
    from sysid.stepper import make_stepper

__getattr__, __dir__, __all__ = attach(__name__, __file__)
__all__ = ["Record", *__all__]
install_aliases()
