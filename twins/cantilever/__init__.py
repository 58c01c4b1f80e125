"""Cantilever micromanipulator twin (dissertation §3.1, ch. 4; physics notes part A).

``CantileverTwin`` simulates u [V] → amplifier → hysteresis (Bouc–Wen or Prandtl–Ishlinskii) + creep →
two-mode dynamics → sensor → y [µm]; see :mod:`twins.cantilever.twin`.
"""

from twins.cantilever.params import CantileverParams
from twins.cantilever.twin import CantileverStepper, CantileverTwin

__all__ = ["CantileverTwin", "CantileverParams", "CantileverStepper"]
