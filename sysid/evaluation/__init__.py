"""How good a model is: validation metrics (R², NRMSE, fit %; dissertation §2.8), the residual correlation tests of
eq. 2-32, one-step and free-run evaluation of any identifier on records, and a practitioner's warnings.

Plain functions on arrays and records; no figures (those are in :mod:`sysid.report`).
May import: :mod:`sysid.errors`, :mod:`sysid.data`.
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.evaluation.advice import closed_loop_correlation, practitioner_warnings
    from sysid.evaluation.evaluate import identification_summary
    from sysid.evaluation.metrics import fit_percent, mse, nrmse, r2, rmse, score
    from sysid.evaluation.residuals import correlation_tests, normality, residual_spectrum, tests_summary, xcorr

__getattr__, __dir__, __all__ = attach(__name__, __file__)
