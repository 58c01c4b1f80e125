"""Polynomial NARX and NARMAX models (dissertation §2.5–2.7): candidate terms and FROLS term selection
(eq. 2-7 … 2-24), the polynomial model every such identifier extends, its compiled one-step / k-step / free-run
predictor (eq. 2-29), and the refinement of a NARX on simulation error (``narx-poly-sim``).

ARX and ARMAX (:mod:`sysid.linear.arx`) are the degree-1 members of this family and build on it.
May import: :mod:`sysid.errors`, :mod:`sysid._blas`, :mod:`sysid.data`, :mod:`sysid.evaluation`,
:mod:`sysid.base`.
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.polynomial.frols import CRITERIA, FrolsResult, Structure, candidate_terms, make_regressors
    from sysid.polynomial.model import PolynomialModel
    from sysid.polynomial.narmax import NARMAXPoly, NARXPoly, check_records
    from sysid.polynomial.polysim import NARXPolySim

__getattr__, __dir__, __all__ = attach(__name__, __file__)
