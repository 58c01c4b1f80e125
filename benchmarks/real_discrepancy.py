"""The discrepancy analysis on measured data: reproducible figures for the README.

``python -m benchmarks.real_discrepancy [--out DIR] [--only piezo,water,narmax]`` writes one JSON per study
and a report folder (figures + index.html) per diagnosis:

- **piezo**: the measured TU/e piezo actuator (benchmarks/data/piezo_tue_150v_1hz; 150 V, 1 Hz, 5 kHz) against
  the cantilever twin in the lab configuration of :func:`twins.cantilever.lab.lab_twin`; first 5 s estimation,
  last 5 s validation (scored as the continuation of the free run).
- **water**: the measured water channel (USbodyComm FIRs, 20 mm, 5 MHz) against the acoustic twin in the lab
  configuration of :mod:`twins.acoustic.labdata` (transducer fitted at 40 mm). The FIRs are impulse
  responses, not I/O records, so measured I/O data are made by convolving test inputs with them: a
  multisine (0.9–1.5 MHz) through FIR #1 for estimation and a chirp through FIR #6 (measured 30 s later) for
  validation.
- **narmax**: the dissertation's Figure 5.6 — its NARMAX orders (ch. 5.1: n_u = 1, n_y = 2, n_e = 3, degree 2,
  ρ_p = 1e-4, ρ_n = 1e-5) fitted to the acoustic twin's first dataset (100 ms chirp, §3.2 preprocessing), and
  the correlation tests of its free-run residual; then the same orders on twin variants (no reverberation, no
  compression, no noise) and higher orders, which shows what makes the tests fail.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.jsonio import clean_json
from sysid.data.record import Record
from sysid.data.safeio import atomic_write_text


def _save(out: Path, name: str, obj: dict[str, Any]) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    p = out / f"{name}.json"
    atomic_write_text(p, json.dumps(clean_json(obj), indent=2))
    return p


def piezo(out: Path) -> dict[str, Any]:
    from benchmarks.datasets import files
    from twins.cantilever.lab import lab_split, lab_twin, static_line_r2
    from twins.discrepancy import run_diagnosis
    from twins.discrepancy.report import write_report

    est, val = lab_split(files.piezo_tue_record())
    # the validation part is one 150 V, 1 Hz sine: give the loop analysis its segment (whole periods at the end)
    val.meta["segments"] = [{"start": 0, "stop": len(val), "freq_hz": 1.0}]
    twin = lab_twin()
    t0 = time.perf_counter()
    diagnosis = run_diagnosis(twin, est, val, max_rounds=3)
    res = diagnosis.to_dict()
    res["seconds"] = time.perf_counter() - t0
    res["static_line_r2_val"] = static_line_r2(est, val)
    write_report(diagnosis.to_dict(keep_stages=True), out / "piezo")
    _save(out, "piezo", res)
    return res


def water_records(distance_mm: int = 20, seed: int = 0) -> tuple[Record, Record]:
    """Measured I/O records from the measured FIRs: multisine through FIR #1, chirp through FIR #6."""
    from benchmarks.datasets import files
    from sysid.signals import excitation as signals
    from twins.acoustic.labdata import FS_FIR, load_charac

    h = load_charac(distance_mm, files.water_fir())
    fs = FS_FIR
    n = 10_000
    u_est = signals.multisine(fs, duration=n / fs, band=(0.9e6, 1.5e6), amplitude=1.0, phase="random", seed=seed)
    u_val = signals.chirp(fs, n / fs, 0.9e6, 1.5e6, amplitude=1.0, method="linear")
    y_est = np.convolve(u_est, h[0])[:n]
    y_val = np.convolve(u_val, h[5])[:n]
    meta = {"source": f"USbodyComm charac_water_{int(distance_mm)}", "fir": "measured impulse response convolved"}
    return (
        Record(u=u_est, y=y_est, fs=fs, meta={**meta, "fir_index": 0}, source="water_est"),
        Record(u=u_val, y=y_val, fs=fs, meta={**meta, "fir_index": 5}, source="water_val"),
    )


def water(out: Path, distance_mm: int = 20) -> dict[str, Any]:
    import dataclasses

    from benchmarks.datasets import files
    from twins.acoustic import AcousticTwin
    from twins.acoustic.amplifier import voltage_gain
    from twins.acoustic.labdata import fit_transducer
    from twins.discrepancy import DiagnoseOptions, run_diagnosis
    from twins.discrepancy.report import write_report

    p40, fit = fit_transducer(40, files.water_fir())
    # the FIR is the electro-acoustic response V_rx/V_oc: the twin's amplifier (V_oc = 2·G_v·u) is divided out
    # through the receive gain, and no amplifier nonlinearity is switched on
    g_amp = 2.0 * voltage_gain(p40.amp_gain_db)
    p = dataclasses.replace(p40, distance_m=distance_mm * 1e-3, output_gain=p40.output_gain / g_amp)
    twin = AcousticTwin(p, effects=set(), seed=0)
    est, val = water_records(distance_mm)
    t0 = time.perf_counter()
    opts = DiagnoseOptions(calibration_params=("pzt_thickness_m", "backing_rayl", "output_gain"))
    diagnosis = run_diagnosis(twin, est, val, max_rounds=3, options=opts)
    res = diagnosis.to_dict()
    res["seconds"] = time.perf_counter() - t0
    res["transducer_fit_40mm"] = fit
    write_report(diagnosis.to_dict(keep_stages=True), out / "water")
    _save(out, "water", res)
    return res


NARMAX_ORDERS = {"nu": 1, "ny": 2, "ne": 3, "degree": 2, "rho_p": 1e-4, "rho_n": 1e-5}  # dissertation ch. 5.1


def _narmax_case(rec: Record, orders: dict[str, Any], n_est: int) -> dict[str, Any]:
    from sysid.evaluation.metrics import r2
    from sysid.evaluation.residuals import correlation_tests
    from sysid.polynomial.narmax import NARMAXPoly
    from twins.discrepancy import features as ft

    est, val = rec[:n_est], rec[n_est:]
    model = NARMAXPoly(
        ny=orders["ny"],
        nu=orders["nu"],
        ne=orders["ne"],
        degree=orders["degree"],
        criterion="err",
        rho_p=orders["rho_p"],
        rho_n=orders["rho_n"],
    )
    model.fit(est)
    out = {"orders": orders, "n_parameters": int(model.n_parameters_)}
    for part, r in (("estimation", est), ("validation", val)):
        yf = model.predict(r, horizon=None)
        y1 = model.predict(r, horizon=1)
        skip = int(model.max_lag_)
        e1 = (r.y - y1)[skip:]
        ef = (r.y - yf)[skip:]
        ct1 = correlation_tests(e1, r.u[skip:], max_lag=20)
        ctf = correlation_tests(ef, r.u[skip:], max_lag=20)
        a = ft.analyse(r.u[skip:], r.output[skip:], yf[skip:], r.fs, {})
        out[part] = {
            "r2_free_run": r2(r.y, yf, skip),
            "r2_one_step": r2(r.y, y1, skip),
            "tests_one_step": ft.tests_summary(ct1),
            "tests_free_run": ft.tests_summary(ctf),
            "residual_echo": a["echo"],
            "residual_resonances": a["resonances"],
            "residual_bands": a["bands"],
            "residual_nonlinear": a["nonlinear"],
            "residual_trend": a["trend"],
        }
    return out


def narmax(out: Path) -> dict[str, Any]:
    """Figure 5.6 explained: NARMAX(1, 2, 3; degree 2) on the acoustic twin's 100 ms chirp dataset."""
    from twins.acoustic import AcousticTwin

    results: dict[str, Any] = {"orders": NARMAX_ORDERS, "cases": {}}
    base = AcousticTwin.from_options(seed=0)
    variants = {
        "default twin (reverberation, compression, noise, 8-bit ADC)": base,
        "no inter-plate reverberation (reverb_orders=0)": base.with_params(reverb_orders=0),
        "no amplifier compression": base.with_effects(base.effects - {"amplifier_compression"}),
        "no noise, no ADC": base.with_effects(base.effects - {"measurement_noise", "adc_quantization"}),
        "bare linear core (no reverberation, compression, noise, ADC)": base.with_params(reverb_orders=0).with_effects(
            set()
        ),
    }
    recs = {}
    for name, tw in variants.items():
        t0 = time.perf_counter()
        rec = tw.generate("thesis-chirp-100ms", preprocess=True, keep=4000, start=20000)
        recs[name] = rec
        try:
            res = _narmax_case(rec, NARMAX_ORDERS, 2000)
        except Exception as exc:  # noqa: BLE001 — report a failing fit instead of losing the other cases
            res = {"error": f"{type(exc).__name__}: {exc}"}
        res["seconds"] = time.perf_counter() - t0
        results["cases"][name] = res
    higher = dict(NARMAX_ORDERS, nu=4, ny=6, ne=4)
    name0 = next(iter(variants))
    try:
        results["higher_orders_on_default"] = _narmax_case(recs[name0], higher, 2000)
    except Exception as exc:  # noqa: BLE001
        results["higher_orders_on_default"] = {"error": f"{type(exc).__name__}: {exc}"}
    _save(out, "narmax_fig56", results)
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="report/discrepancy", help="output folder")
    ap.add_argument("--only", default="piezo,water,narmax")
    args = ap.parse_args(argv)
    out = Path(args.out)
    for name in [s.strip() for s in args.only.split(",") if s.strip()]:
        t0 = time.perf_counter()
        res = {"piezo": piezo, "water": water, "narmax": narmax}[name](out)
        summary = {k: res.get(k) for k in ("verdict", "gain", "baseline", "extended")} if "verdict" in res else {}
        print(name, f"{time.perf_counter() - t0:.0f} s", json.dumps(clean_json(summary))[:2000])
        if "causes" in res:
            for c in res["causes"]:
                print("  cause", c["effect"], round(c["confidence"], 3), c["params"])
                print("   ", c["evidence"])
            print("  unexplained:", res["unexplained"])
        if res.get("hybrid"):
            from twins.discrepancy.hybrid import hybrid_text

            print(" ", hybrid_text(res["hybrid"]))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
