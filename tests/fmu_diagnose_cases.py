"""Hidden-effect cases for the diagnosis of the cantilever FMU (``fmus/cantilever.fmu``) and of the native
cantilever kernel wrapped as a user's model, on the records of :mod:`discrepancy_cases`.

The FMU is configured as the native twin the native diagnosis starts from: its measurement noise off (noise is
never predicted), its quantiser replaced by the generic ``output_quantization`` at the same 10 nm step (on, so
that it is not a candidate: the data carry it as the native start twin does); for the sensor case its own sensor
off, so that the generic ``sensor_lowpass`` is what the diagnosis can add. Records are cut to ``n`` samples per
record (the FMU steps 20 µs per sample through its Python slave: a full-length diagnosis would take ~30 min).
"""

from __future__ import annotations

from pathlib import Path

from discrepancy_cases import hidden_case

ROOT = Path(__file__).resolve().parents[1]
FMU = ROOT / "fmus" / "cantilever.fmu"
#: the cases of the issue: the native twin's cause and the fields checked within 10 %
CASES = {"input_delay": ["input_delay_s"], "sensor_lowpass": ["sensor_bandwidth_hz"],
         "thermal_drift": ["thermal_drift_um", "thermal_tau_s"]}
#: core parameters calibrated with every trial (a subset of the native CALIBRATION_PARAMS: each costs FMU runs)
CORE = ("gain_um_per_v", "f1_hz", "zeta1", "offset_um")


def fmu_case(effect: str | None, seed: int, n: int = 2500):
    """(FMU twin as configured, est, val, true parameters, checked fields) for one case (None = noise only)."""
    from twins.external import fmu_twin_class

    _, est, val, params, checked = hidden_case("cantilever", effect, seed)
    est, val = est[:n], val[-n:]
    cls = fmu_twin_class(FMU, list(CORE))
    off = "effect_measurement_noise=false,effect_sensor_quantization=false"
    if effect == "sensor_lowpass":
        off += ",effect_sensor_lowpass=false"
    twin = cls.from_options(set_=[off], effect=["output_quantization:step=0.01"])
    return twin, est, val, params, checked


def same_cause(native_effect: str, cause: dict, twin) -> bool:
    """The cause names the generic effect the native one specialises (or it, in its group)."""
    from twins.cantilever.effects import EFFECTS

    want = EFFECTS[native_effect].generic or native_effect
    return cause.get("effect") == want or want in cause.get("group", [])


def generic_value(twin, cause: dict, native_field: str) -> float | None:
    """The fitted value of the generic parameter that corresponds to a native one (same law, own name)."""
    from twins.cantilever.effects import EFFECTS

    for e in EFFECTS.values():
        for key, f in e.params.items():
            if f == native_field and e.generic:
                gfield = twin.EFFECTS[e.generic].params[key]
                return cause.get("params", {}).get(gfield)
    return None
