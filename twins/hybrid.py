"""The hybrid twin: a physics twin plus a black-box model of what it leaves unexplained.

When a diagnosis ends with a residual far above the noise and no catalog effect explains it (verdict
``unexplained``), the remainder is still data: ``r = y − ŷ_twin``. :class:`HybridTwin` fits it with one of the
project's own identifiers (:mod:`sysid.registry`) on the inputs [u, ŷ_twin] — the drive and the twin's simulated
output, each scaled by its standard deviation on the estimation record — so that

    ŷ_hybrid[k] = ŷ_twin[k] + r̂[k],   r̂ = M(u/s_u, ŷ_twin/s_y) · s_r   (free run, zero initial conditions)

is a simulation model like the twin itself: it needs the input alone (no measured output), and it is scored by
free-run simulation on validation data like every identifier (Ljung 1999 §16.4 calls this a "semi-physical"
or grey-box-plus-black-box model; Sohlberg & Jacobsen 2008 the "hybrid" with a black-box error model). The
identifier is chosen among a few small structures by the *estimation* record's free-run error (the validation
record is kept for the score that is reported). The physics stays as diagnosed: a black-box remainder names no
cause.

``save(path)`` writes one JSON file (the twin's configuration and the remainder model in the project's model-file
format, :mod:`sysid.data.modelfile`); :meth:`HybridTwin.load` reads it back and simulates identically.
"""

from __future__ import annotations

import copy
import json
import math
import tempfile
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.jsonio import read_json_file
from sysid.data.modelfile import read_model
from sysid.data.record import Record
from sysid.data.safeio import atomic_write_text
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.evaluation.metrics import nrmse, r2
from sysid.registry import get_identifier
from twins.base import Twin

__all__ = ["HybridTwin", "HybridStepper", "DEFAULT_CANDIDATES", "HYBRID_FORMAT"]

HYBRID_FORMAT = "piezotwin-hybrid-1"

#: remainder structures tried (identifier, settings): a linear ARX with direct feed-through and a cubic NARX
#: (FROLS, BIC) over two lags of the remainder and of each input — small enough to fit in seconds on 10⁵ samples
DEFAULT_CANDIDATES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("arx", {"ny": 2, "nu": 3, "nk": 0, "orders": "given"}),
    ("narx-poly", {"ny": 2, "nu": 2, "nk": 0, "degree": 3, "max_terms": 30}),
)


def _scale(x: np.ndarray) -> float:
    s = float(np.std(x))
    return s if math.isfinite(s) and s > 0 else 1.0


class HybridStepper:
    """One sample of a hybrid twin: ``y = y_twin + s_r·M(u/s_u, y_twin/s_y)`` with the physics core and the
    remainder model's stepper each advanced by one sample (both from rest after :meth:`reset`)."""

    def __init__(self, physics_core: Any, remainder: Any, scales: dict[str, float]):
        self.physics_core, self.remainder = physics_core, remainder
        self.su, self.sy, self.sr = float(scales["u"]), float(scales["y_twin"]), float(scales["r"])

    def reset(self) -> None:
        self.physics_core.reset()
        self.remainder.reset()

    def step(self, u: float) -> float:
        yt = float(self.physics_core.step(u))
        return yt + float(self.remainder.step((float(u) / self.su, yt / self.sy))) * self.sr


class HybridTwin:
    """Physics twin + black-box remainder (module docstring).

    Parameters
    ----------
    physics : the twin (deterministic: its noise and quantisation effects are best switched off, as the
        diagnosis' prediction does).
    candidates : (identifier, settings) pairs tried; the one with the smallest free-run SSE on the estimation
        record is kept.

    Attributes (after :meth:`fit`)
    ------------------------------
    model_ : the fitted remainder identifier; ``identifier_``, ``settings_`` its id and settings;
    scales_ : {"u", "y_twin", "r"} the input and output scales; ``fit_table_`` one row per candidate.
    """

    def __init__(self, physics: Twin, candidates: Sequence[tuple[str, dict[str, Any]]] = DEFAULT_CANDIDATES):
        self.physics = physics
        self.candidates = candidates

    # ------------------------------------------------------------------ the model
    @property
    def name(self) -> str:
        return f"hybrid({self.physics.name})"

    @property
    def units(self) -> dict[str, str]:
        return dict(self.physics.units)

    def _inputs(self, u: np.ndarray, y_twin: np.ndarray) -> np.ndarray:
        s = self.scales_
        return np.column_stack([np.asarray(u, float) / s["u"], np.asarray(y_twin, float) / s["y_twin"]])

    def remainder(self, u: np.ndarray, y_twin: np.ndarray, fs: float) -> np.ndarray:
        """Free-run remainder r̂ for the drive ``u`` and the twin's output ``y_twin`` (zero initial conditions)."""
        self._check_fitted()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DivergenceWarning)  # a diverged free run is NaN from there on
            r = self.model_.predict(Record(u=self._inputs(u, y_twin), y=None, fs=fs), horizon=None)
        return np.asarray(r, float).reshape(-1) * self.scales_["r"]

    def simulate(self, u: np.ndarray, fs: float) -> np.ndarray:
        """ŷ_twin + r̂ for the drive ``u`` at ``fs`` [Hz] (the twin starts at rest, the remainder from zero)."""
        y_twin = np.asarray(self.physics.simulate(u, fs), float)
        return y_twin + self.remainder(u, y_twin, fs)

    def with_params(self, **changes: Any) -> HybridTwin:
        """The same hybrid, its fitted remainder kept, with some of the physics twin's parameters changed (a
        record's own start state: :func:`twins.discrepancy.prediction.simulate_val`)."""
        new = copy.copy(self)
        new.physics = self.physics.with_params(**changes)
        return new

    @property
    def fs_(self) -> float | None:
        """Sampling rate [Hz] of the remainder model (its estimation record's): the rate of its discrete-time
        free run, so the rate a per-sample stepper or an FMU of the hybrid must run at."""
        self._check_fitted()
        fs = getattr(self.model_, "fs_", None)
        return float(fs) if fs else None

    def make_stepper(self, fs: float, core: dict[str, Any] | None = None) -> HybridStepper:
        """Sample-by-sample simulator (``reset()``, ``step(u) -> y``) for FMU export: the physics twin's own
        per-sample core (:mod:`twins.fmu.cores`: its stepper, or the response core of a block-simulated twin)
        and the remainder model's stepper (:func:`sysid.stepper.make_stepper`, its free-run kernel) on
        [u/s_u, ŷ_twin/s_y]. With a stepper core it reproduces :meth:`simulate` sample for sample. ``fs`` [Hz]
        must be the remainder's rate (:attr:`fs_`)."""
        from sysid.stepper import make_stepper
        from twins.fmu.cores import build_core, choose_core

        own = self.fs_
        if own is not None and abs(float(fs) - own) > 1e-9 * own:
            raise ConfigError(
                f"hybrid twin: its remainder model is discrete-time at {own:g} Hz; it cannot step at {float(fs):g} Hz"
            )
        core = dict(core) if core is not None else choose_core(self.physics, fs)
        return HybridStepper(build_core(self.physics, fs, core), make_stepper(self.model_), dict(self.scales_))

    # ------------------------------------------------------------------ fitting
    def fit(self, est: Record, skip: int = 0) -> HybridTwin:
        """Fit the remainder of ``est`` (the twin's free-run residual) with each candidate; keep the one whose
        free-run hybrid prediction has the smallest estimation SSE after ``skip`` samples."""
        est.require_output()
        if est.n_inputs != 1 or est.n_outputs != 1:
            raise DataError(f"{est.source}: the hybrid twin handles single-input single-output records")
        if not self.candidates:
            raise ConfigError("hybrid twin: no remainder identifier to try")
        y = np.asarray(est.output, float).reshape(-1)
        y_twin = np.asarray(self.physics.simulate(est.u, est.fs), float)
        r = y - y_twin
        self.scales_ = {"u": _scale(est.u), "y_twin": _scale(y_twin), "r": _scale(r)}
        rec = Record(
            u=self._inputs(est.u, y_twin), y=r / self.scales_["r"], fs=est.fs, source=f"{est.source} remainder"
        )
        table: list[dict[str, Any]] = []
        best: tuple[float, Any, str, dict[str, Any]] | None = None
        for ident, settings in self.candidates:
            t0 = time.perf_counter()
            row: dict[str, Any] = {"identifier": ident, "settings": dict(settings)}
            try:
                model = get_identifier(ident)(**settings).fit(rec)
                self.model_ = model
                rh = self.remainder(est.u, y_twin, est.fs)
                e = r[skip:] - rh[skip:]
                cost = float(np.sum(e * e)) if np.all(np.isfinite(e)) else float("inf")
            except (ConfigError, DataError, ValueError, np.linalg.LinAlgError) as exc:
                row["error"] = str(exc)
                cost, model = float("inf"), None
            row.update(sse_est=cost, seconds=time.perf_counter() - t0)
            table.append(row)
            if model is not None and math.isfinite(cost) and (best is None or cost < best[0]):
                best = (cost, model, ident, dict(settings))
        if best is None:
            raise DataError(
                "hybrid twin: no remainder model could be fitted: "
                + "; ".join(f"{r['identifier']}: {r.get('error', 'free run diverged')}" for r in table)
            )
        _, self.model_, self.identifier_, self.settings_ = best
        self.fit_table_ = table
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "model_"):
            raise ConfigError("hybrid twin: not fitted (call fit first)")

    def score(self, rec: Record, skip: int = 0) -> dict[str, float]:
        """R² and NRMSE of the twin alone and of the hybrid on ``rec`` (free run from rest)."""
        rec.require_output()
        y_twin = np.asarray(self.physics.simulate(rec.u, rec.fs), float)
        yh = y_twin + self.remainder(rec.u, y_twin, rec.fs)
        y = np.asarray(rec.output, float).reshape(-1)
        return {
            "r2_twin": r2(y, y_twin, skip),
            "nrmse_twin": nrmse(y, y_twin, skip),
            "r2_hybrid": r2(y, yh, skip),
            "nrmse_hybrid": nrmse(y, yh, skip),
        }

    def describe(self) -> dict[str, Any]:
        """JSON-able summary: the twin, the remainder's identifier, settings, inputs and scales."""
        self._check_fitted()
        return {
            "twin": self.physics.name,
            "effects": sorted(self.physics.effects),
            "identifier": self.identifier_,
            "settings": self.settings_,
            "inputs": ["u", "y_twin"],
            "scales": dict(self.scales_),
            "n_parameters": getattr(self.model_, "n_parameters_", None),
        }

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        """Write the hybrid twin to ``path`` (JSON, atomically): the twin's configuration and the remainder model."""
        self._check_fitted()
        with tempfile.TemporaryDirectory() as d:
            tmp = Path(d) / "remainder.json"
            self.model_.save(tmp)
            remainder = json.loads(tmp.read_text())
        doc = {
            "format": HYBRID_FORMAT,
            "physics": self.physics.config(),
            "identifier": self.identifier_,
            "settings": self.settings_,
            "scales": self.scales_,
            "remainder": remainder,
        }
        return atomic_write_text(path, json.dumps(doc))

    @classmethod
    def load(cls, path: str | Path) -> HybridTwin:
        """Read a file written by :meth:`save` (the physics twin must be a shipped one, :mod:`twins.registry`)."""
        from twins.registry import get_twin

        doc = read_json_file(path, HYBRID_FORMAT, "hybrid twin file")
        phys = doc["physics"]
        tcls = get_twin(phys["twin"])
        physics = tcls(tcls.Params(**phys["params"]), phys["effects"], phys["seed"])
        out = cls(physics, [(doc["identifier"], doc["settings"])])
        with tempfile.TemporaryDirectory() as d:
            tmp = Path(d) / "remainder.json"
            tmp.write_text(json.dumps(doc["remainder"]))
            out.model_ = read_model(tmp)
        out.identifier_, out.settings_, out.scales_ = doc["identifier"], doc["settings"], dict(doc["scales"])
        out.fit_table_ = []
        return out
