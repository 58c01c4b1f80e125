"""Studies of the acoustic channel: the figures ``piezotwin sweep`` tabulates for each parameter value.

For each configuration: the peak frequency, peak gain and −3 dB bandwidth of the direct-path (gated)
transmission |V_rx/V_oc| in 900–1350 kHz, the time of flight (envelope peak of the band-limited response,
which includes the transducers' group delay) and L/c, and — when the identifiers are in the build — the
free-run R² of an ARX model identified on the dissertation's preprocessed multisine and validated on its
preprocessed 1 ms chirp (otherwise ``identified_model_r2`` is null and ``identified_model_note`` says why).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["sweep_metrics", "sweep_spectrum"]


def _identified_accuracy(twin, protocol: str | None, identifier: str = "arx") -> dict[str, Any]:
    """Free-run R² of an identified linear model on the twin's data, or a null with the reason.

    Estimation: the protocol (default ``thesis-multisine``) with the §3.2 recipe; validation:
    ``thesis-chirp-1ms`` with the recipe. ARX orders ny = 4, nu = 8 and the input delay n_k from the twin's
    time of flight at 6.75 MHz (the dissertation's models had no way to span the ≈500-sample delay).
    """
    try:
        from sysid.registry import get_identifier

        cls = get_identifier(identifier)
    except Exception as exc:  # a build without the identifier's dependencies: the column is null, with the reason
        return {
            "identified_model_r2": None,
            "identified_model_note": f"{exc} — left null until the identifiers are merged",
        }
    from sysid.evaluation.metrics import r2 as _r2
    from twins.acoustic.protocols import FS_RECIPE

    est_p = protocol or "thesis-multisine"
    if est_p == "vna-sweep":
        return {"identified_model_r2": None, "identified_model_note": "vna-sweep has no time record to identify"}
    est = twin.generate(est_p, duration=0.004, preprocess=True)
    val = twin.generate("thesis-chirp-1ms", duration=0.004, preprocess=True)
    nk = max(1, int(round(twin.time_of_flight() * FS_RECIPE)) - 4)
    try:
        model = cls(ny=4, nu=8, nk=nk).fit(est)
        yh = model.predict(val, horizon=None)
        return {
            "identified_model_r2": float(_r2(val.y, yh)),
            "identified_model_note": f"{identifier}(ny=4, nu=8, nk={nk}) on {est_p}+recipe, free run on "
            "thesis-chirp-1ms+recipe",
        }
    except Exception as exc:
        return {"identified_model_r2": None, "identified_model_note": f"{identifier} failed: {exc}"}


def sweep_metrics(twin, protocol: str | None = None, identify: bool = True) -> dict[str, Any]:
    """Figures of ``piezotwin sweep``: peak frequency/gain, −3 dB bandwidth, time of flight (+ identified-model
    accuracy, null when no identifier could be fitted). :meth:`AcousticTwin.sweep_metrics` calls this."""
    out: dict[str, Any] = dict(twin.spectrum_metrics())
    if identify:
        out.update(_identified_accuracy(twin, protocol))
    return out


def sweep_spectrum(twin, band=(0.5e6, 2.0e6), points: int = 2000) -> tuple[np.ndarray, dict]:
    """(f, {"direct": dB, "full": dB}) of |V_rx/V_oc| for the sweep report's spectrum plot."""
    f = np.linspace(band[0], band[1], points)
    direct = 20 * np.log10(np.abs(twin.frequency_response(f, direct_only=True, include_amplifier=False)) + 1e-300)
    full = 20 * np.log10(np.abs(twin.frequency_response(f, include_amplifier=False)) + 1e-300)
    return f, {"direct": direct, "full": full}
