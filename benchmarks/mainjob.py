"""The main job (``piezotwin run``, what ``make run`` starts): each stage is a function ``stage(ctx) -> str``
(a one-line account of what it did).

Stages, in order: the dissertation's excitation signals; the twins' datasets (cantilever thesis-multisine →
thesis-sines, acoustic multisine → 1 ms chirp after the preprocessing recipe; with and without measurement
noise); figures of the twins (hysteresis loops, spectra, the VNA-style response); every identifier on the twin
datasets; every identifier on the recorded lab benchmarks beside the published numbers, SysIdentPy and the
stored records; one discrepancy diagnosis; a distance/temperature sweep of the acoustic channel; then
``report/index.html`` with every figure (relative paths, opens without a server).

A stage whose parts are not built yet raises :class:`StageSkipped`; the job goes on and says so. A stage that
fails is reported as failed (with the error) and the job goes on; ``piezotwin run`` then exits 1.
Budgets: the default run is sized for ≤ 10 minutes on 2 cores, ``--quick`` for ≤ 2 minutes. The identifiers are
fitted at the quick check's budgets and judged against the floors measured at those budgets; the records table's
full-budget rows are shown as stored (:mod:`benchmarks.mainjob_score`). Each stage logs its time; the report's
header says how long the run took, how many rows are below their floor, and names everything the run did not
recompute with the command that does.
"""

from __future__ import annotations

import logging
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.mainjob_context import Context, StageSkipped
from benchmarks.mainjob_score import stage_identify_twins, stage_lab
from sysid.report.html import esc, figure, table, write_page
from sysid.report.plots import pyplot

__all__ = ["STAGES", "Context", "StageSkipped", "floor_counts", "run_main_job"]


log = logging.getLogger(__name__)


def _not_built(exc: Exception, what: str) -> StageSkipped:
    return StageSkipped(f"{what} not built yet ({exc})")


# ---------------------------------------------------------------------------------------------- stages
def _stage_signals(ctx: Context) -> str:
    try:
        from sysid.signals import excitation as signals
    except ImportError:
        raise StageSkipped("sysid.signals not built yet") from None
    # 5000 lines up to 500 Hz need a 0.1 Hz grid (10 s period); the 8 s record is 80 % of it (see the docstring)
    u, info = signals.thesis_cantilever_multisine(seed=0, return_info=True)
    ctx.data["cantilever_multisine_u"] = u
    return (
        f"dissertation multisine: {u.size} samples at 10 kHz, {info['n_components']} lines up to"
        f" {info['frequencies_hz'][-1]:g} Hz, crest factor {info['crest_factor']:.2f}"
    )


def _twin_dataset_names() -> list[str]:
    from benchmarks.datasets import twin as twin_ds

    return list(twin_ds.TWIN_DATASETS)


def _stage_twin_datasets(ctx: Context) -> str:
    from benchmarks.datasets import list_datasets, load_dataset

    info = {d["id"]: d for d in list_datasets()}
    done, skipped = [], []
    for name in _twin_dataset_names():
        if not info[name]["available"]:
            skipped.append(name)
            continue
        t0 = time.perf_counter()
        ds = load_dataset(name, progress=ctx.verbose)
        ctx.data.setdefault("twin_datasets", {})[name] = ds
        done.append(
            f"{name} ({len(ds.est)} -> {', '.join(f'{k} {len(v)}' for k, v in ds.tests.items())} samples, "
            f"{time.perf_counter() - t0:.1f} s)"
        )
    if not done:
        raise StageSkipped(f"no twin built yet ({', '.join(skipped)} unavailable)")
    msg = "; ".join(done)
    if skipped:
        msg += f"; skipped (twin not built): {', '.join(skipped)}"
    return msg


def _spectrum(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float) - np.mean(x)
    X = np.fft.rfft(x * np.hanning(x.size))
    f = np.fft.rfftfreq(x.size, 1.0 / fs)
    return f, 20 * np.log10(np.abs(X) / x.size + 1e-300)


def _stage_cantilever_figures(ctx: Context) -> str:
    ds = ctx.data.get("twin_datasets", {}).get("cantilever-thesis")
    if ds is None:
        raise StageSkipped("no cantilever dataset (cantilever twin not built)")
    plt = pyplot()
    test = ds.tests["thesis-sines"]
    segs = test.segments()
    n = len(segs)
    cols = 4
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(11, 2.6 * rows))
    from sysid.report.plots import whole_periods

    for ax, seg in zip(np.ravel(axes), segs):
        f = seg.meta["segment"].get("freq_hz")
        last = whole_periods(len(seg), seg.fs, f)  # the last whole period: a closed loop (0.1 Hz: the whole 10 s)
        ax.plot(seg.u[last], seg.y[last], lw=0.6)
        ax.set_title(f"{f:g} Hz (last {(last.stop - last.start) * f / seg.fs:.3g} period)", fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in np.ravel(axes)[n:]:
        ax.axis("off")
    fig.suptitle("cantilever twin: u-y loops for the thesis sines (Figure 4.3 analogue; x: V, y: µm)")
    fig.tight_layout()
    ctx.save_figure(fig, "cantilever_loops", "Cantilever twin: hysteresis loops at each thesis sine (u [V] vs y [µm])")
    est = ds.est
    fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    for a, x, lab in ((ax[0], est.u, "input u [V]"), (ax[1], est.y, "output y [µm]")):
        f, s = _spectrum(x, est.fs)
        a.plot(f, s, lw=0.5)
        a.set_ylabel(f"{lab}\n[dB]")
        a.set_xlim(0, 1500)
    ax[1].set_xlabel("frequency [Hz]")
    fig.suptitle("cantilever twin: thesis-multisine spectra (Figure 3.4 analogue)")
    fig.tight_layout()
    ctx.save_figure(
        fig, "cantilever_multisine_spectra", "Cantilever twin: input and output spectra of the thesis multisine"
    )
    widths = []
    for seg in segs[:2]:
        last = whole_periods(len(seg), seg.fs, seg.meta["segment"].get("freq_hz"))
        y, u = seg.y[last], seg.u[last]
        up = np.gradient(u) > 0
        grid = np.linspace(-0.5, 0.5, 21) * np.ptp(u)
        try:
            yu = np.interp(grid, u[up][np.argsort(u[up])], y[up][np.argsort(u[up])])
            yd = np.interp(grid, u[~up][np.argsort(u[~up])], y[~up][np.argsort(u[~up])])
            widths.append(float(np.max(np.abs(yu - yd)) / np.ptp(y)))
        except ValueError:
            pass
    w = ", ".join(f"{100 * x:.1f} %" for x in widths)
    return f"loops for {n} sines, multisine spectra; loop width/span at the two lowest frequencies: {w or 'n/a'}"


def _stage_acoustic_figures(ctx: Context) -> str:
    ds = ctx.data.get("twin_datasets", {}).get("acoustic-thesis")
    if ds is None:
        raise StageSkipped("no acoustic dataset (acoustic twin not built)")
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11, 5.5))
    for col, (title, rec) in enumerate(
        (("multisine (estimation)", ds.est), ("1 ms chirp (test)", next(iter(ds.tests.values()))))
    ):
        for row, (x, lab) in enumerate(((rec.u, "input [V]"), (rec.y, "output [V]"))):
            f, s = _spectrum(x, rec.fs)
            axes[row, col].plot(f / 1e3, s, lw=0.5)
            axes[row, col].set_xlim(0, rec.fs / 2e3)
            axes[row, col].set_ylabel(f"{lab} [dB]", fontsize=8)
            axes[row, col].axvspan(900, 1350, color="0.9", zorder=0)
        axes[0, col].set_title(f"{title}, after preprocessing", fontsize=9)
        axes[1, col].set_xlabel("frequency [kHz]")
    fig.suptitle("acoustic twin: spectra after the dissertation's preprocessing (Figures 3.12 / 3.14 analogue)")
    fig.tight_layout()
    ctx.save_figure(fig, "acoustic_spectra", "Acoustic twin: input/output spectra of the multisine and the 1 ms chirp")
    from twins.registry import get_twin

    tw = get_twin("acoustic")()
    vna = tw.generate("vna-sweep", f_start=500e3, f_stop=2.0e6, points=1500)
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ax.plot(vna.u / 1e3, vna.y, lw=0.8)
    ax.axvspan(900, 1350, color="0.9", zorder=0)
    ax.set_xlabel("frequency [kHz]")
    ax.set_ylabel(f"magnitude [{vna.units.get('y', 'dB')}]")
    ax.set_title("acoustic twin: VNA-style magnitude response (Figure 3.9 analogue)")
    fig.tight_layout()
    ctx.save_figure(fig, "acoustic_vna", "Acoustic twin: magnitude response, useful band shaded")
    m = tw.spectrum_metrics()
    return (
        f"spectra of {len(ds.est)}/{len(next(iter(ds.tests.values())))} preprocessed samples; peak "
        f"{m['peak_frequency_hz'] / 1e3:.0f} kHz, -3 dB bandwidth {m['bandwidth_hz'] / 1e3:.0f} kHz"
    )


def _stage_discrepancy(ctx: Context) -> str:
    try:
        from twins.discrepancy import diagnose
        from twins.discrepancy.report import write_report
        from twins.registry import get_twin
    except ImportError as exc:
        raise _not_built(exc, "twins.discrepancy") from None
    from sysid.errors import ConfigError

    try:
        cls = get_twin("cantilever")
    except ConfigError as exc:
        raise StageSkipped(str(exc)) from None
    # "measured" data: the twin WITH creep (and noise); the model under test: the twin without creep.
    truth = cls(None, set(cls.default_effects()) | {"creep"}, seed=1)
    hold = 5.0 if ctx.quick else 10.0
    data = truth.generate("steps", hold_s=hold)
    val = truth.generate("steps", hold_s=hold, level_v=50.0)  # held-out: other step height, same rate
    start = cls(None, set(cls.default_effects()) - {"creep"}, seed=1)
    cands = ["creep", "thermal_drift", "input_delay"] if ctx.quick else None
    res = diagnose(start, data, val, max_rounds=1, candidates=cands, keep_stages=True)
    sub = ctx.report_dir / "discrepancy"
    index = write_report(res, sub)
    for png in sorted(sub.glob("*.png")):
        ctx.figures.append((f"Discrepancy diagnosis: {png.stem.replace('_', ' ')}", f"discrepancy/{png.name}"))
    causes = ", ".join(c["effect"] for c in res.get("causes", [])) or "none"
    b, e = res["baseline"], res["extended"]
    ctx.section(
        "Discrepancy diagnosis",
        f"<p>Cantilever twin without creep vs data from the twin with creep (steps): "
        f"verdict <b>{esc(res['verdict'])}</b>, causes: {esc(causes)}; validation NRMSE "
        f"{b['nrmse_val']:.4g} → {e['nrmse_val']:.4g}. <a href='discrepancy/{index.name}'>full diagnosis</a></p>",
    )
    return f"hidden effect creep -> found: {causes}; validation NRMSE {b['nrmse_val']:.4g} -> {e['nrmse_val']:.4g}"


def _stage_sweep(ctx: Context) -> str:
    from sysid.errors import ConfigError
    from twins.registry import get_twin

    try:
        cls = get_twin("acoustic")
    except ConfigError as exc:
        raise StageSkipped(str(exc)) from None
    base = cls()
    if not hasattr(base, "spectrum_metrics"):
        raise StageSkipped("acoustic twin has no spectrum_metrics yet")
    plt = pyplot()
    distances = [0.05, 0.1, 0.15, 0.2] if ctx.quick else [0.05, 0.075, 0.1, 0.125, 0.15, 0.2, 0.3]
    temps = [15.0, 24.0, 35.0] if ctx.quick else [10.0, 15.0, 20.0, 24.0, 30.0, 35.0, 40.0]
    f = np.linspace(800e3, 1450e3, 600)
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.4))
    rows = []
    for d in distances:
        tw = base.with_params(distance_m=d)
        m = tw.spectrum_metrics()
        rows.append(("distance_m", d, m))
        h = tw.frequency_response(f, direct_only=True, include_amplifier=False)
        ax[0].plot(f / 1e3, 20 * np.log10(np.abs(h) + 1e-300), lw=0.8, label=f"{d * 100:g} cm")
    for t in temps:
        rows.append(("temperature_c", t, base.with_params(temperature_c=t).spectrum_metrics()))
    ax[0].set_xlabel("frequency [kHz]")
    ax[0].set_ylabel("gain [dB]")
    ax[0].legend(fontsize=7)
    ax[0].set_title("direct-path response vs distance", fontsize=9)
    dd = [(v, m) for p, v, m in rows if p == "distance_m"]
    ax[1].plot([v * 100 for v, _ in dd], [m["peak_gain_db"] for _, m in dd], "o-")
    ax[1].set_xlabel("distance [cm]")
    ax[1].set_ylabel("peak gain [dB]")
    ax2 = ax[1].twinx()
    ax2.plot([v * 100 for v, _ in dd], [m["time_of_flight_s"] * 1e6 for _, m in dd], "s--", color="C1")
    ax2.set_ylabel("time of flight [µs]", color="C1")
    tt = [(v, m) for p, v, m in rows if p == "temperature_c"]
    ax[2].plot([v for v, _ in tt], [m["peak_frequency_hz"] / 1e3 for _, m in tt], "o-")
    ax[2].set_xlabel("water temperature [°C]")
    ax[2].set_ylabel("peak frequency [kHz]")
    ax3 = ax[2].twinx()
    ax3.plot([v for v, _ in tt], [m["time_of_flight_s"] * 1e6 for _, m in tt], "s--", color="C1")
    ax3.set_ylabel("time of flight [µs]", color="C1")
    fig.suptitle("acoustic twin: distance and temperature sweeps")
    fig.tight_layout()
    ctx.save_figure(
        fig, "acoustic_sweep", "Acoustic twin: response, peak gain and time of flight against distance and temperature"
    )
    tab = table(
        [
            "parameter",
            "value",
            "peak frequency [kHz]",
            "peak gain [dB]",
            "-3 dB bandwidth [kHz]",
            "time of flight [µs]",
        ],
        [
            [
                p,
                f"{v:g}",
                f"{m['peak_frequency_hz'] / 1e3:.1f}",
                f"{m['peak_gain_db']:.2f}",
                f"{m['bandwidth_hz'] / 1e3:.1f}",
                f"{m['time_of_flight_s'] * 1e6:.2f}",
            ]
            for p, v, m in rows
        ],
        cls="score",
    )
    ctx.section("Acoustic channel sweep", tab)
    tof = [m["time_of_flight_s"] for _, m in dd]
    return (
        f"{len(distances)} distances, {len(temps)} temperatures; time of flight {tof[0] * 1e6:.1f} -> "
        f"{tof[-1] * 1e6:.1f} µs over {distances[0] * 100:g}-{distances[-1] * 100:g} cm"
    )


STAGES: list[tuple[str, Callable[[Context], str]]] = [
    ("excitation signals", _stage_signals),
    ("twin datasets", _stage_twin_datasets),
    ("cantilever figures", _stage_cantilever_figures),
    ("acoustic figures", _stage_acoustic_figures),
    ("identify twin datasets", stage_identify_twins),
    ("score lab benchmarks", stage_lab),
    ("discrepancy diagnosis", _stage_discrepancy),
    ("acoustic sweep", _stage_sweep),
]


# ---------------------------------------------------------------------------------------------- report
_CSS = (
    "body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em}"
    "figure{margin:1em 0}.skipped{color:#888}.failed{color:#b00}"
)


def _minutes(seconds: float) -> str:
    return f"{int(seconds // 60)} min {seconds % 60:.0f} s"


def floor_counts(ctx: Context) -> dict[str, int]:
    """Rows of the scoring stages judged against a floor at their budget, below it, and not compared (no floor)."""
    keys = [k for k in ("twins", "lab") if f"{k}_compared" in ctx.data]
    return {
        "compared": sum(ctx.data[f"{k}_compared"] for k in keys),
        "below_floor": sum(len(ctx.data[f"{k}_check"]) for k in keys),
        "not_compared": sum(len(ctx.data[f"{k}_not_compared"]) for k in keys),
    }


def _header(ctx: Context, seconds: float | None) -> str:
    """How long the run took, how its rows compare with the floors, and what it left to other commands."""
    mode = "quick" if ctx.quick else "default"
    took = f" The run took {_minutes(seconds)}." if seconds is not None else ""
    n = floor_counts(ctx)
    floors = (
        f"<p>Rows judged against a floor measured at the same budget: {n['compared']}, below their floor: "
        f"<b>{n['below_floor']}</b>; without a floor at that budget (not compared): {n['not_compared']}.</p>"
        if n["compared"] or n["not_compared"]
        else ""
    )
    left = (
        (
            "<p>Not recomputed by this run (stored or left to the command shown):</p><ul>"
            + "".join(f"<li>{esc(what)} ({esc(why)}): <code>{esc(cmd)}</code></li>" for what, why, cmd in ctx.left)
            + "</ul>"
        )
        if ctx.left
        else ""
    )
    return (
        f"<h1>PiezoTwin main job</h1><p>Mode: {mode}. Generated "
        f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}.{took}</p>" + floors + left
    )


def _write_report(ctx: Context, rows: list[dict[str, Any]], seconds: float | None = None) -> Path:
    from sysid.report.provenance import collect

    ctx.report_dir.mkdir(parents=True, exist_ok=True)
    body = [
        _header(ctx, seconds),
        table(
            ["stage", "status", "result", "s"],
            [[esc(r["stage"]), r["status"], esc(r["message"]), f"{r['seconds']:.1f}"] for r in rows],
            row_classes=[r["status"] for r in rows],
        ),
    ]
    body += [f"<h2>{esc(title)}</h2>{content}" for title, content in ctx.sections]
    if ctx.figures:
        body.append("<h2>Figures</h2>")
    body += [figure(src, title) for title, src in ctx.figures]
    # the vendored lab data the lab stage reads; the twin datasets are generated in the run (their protocols
    # and the commit above define them)
    lab_done = any(r["stage"] == "score lab benchmarks" and r["status"] == "done" for r in rows)
    return write_page(
        ctx.report_dir / "index.html",
        "PiezoTwin report",
        body,
        css=_CSS,
        provenance=collect(files=_scored_lab_files() if lab_done else []),
    )


def _scored_lab_files() -> list[Path]:
    """The record files of the scored lab datasets, as the dataset registry resolves them."""
    from benchmarks.datasets import files

    return sorted(p for name in files.SCORED_LAB for p in files.get(name).paths())


def run_main_job(
    report_dir: str | Path = "report", quick: bool = False, verbose: bool = True, stages: list[str] | None = None
) -> dict[str, Any]:
    """Run the stages (all, or those named in ``stages``), write ``report_dir/index.html``; return a summary."""
    ctx = Context(report_dir=Path(report_dir), quick=quick, verbose=verbose)
    rows = []
    t_all = time.perf_counter()
    for name, fn in STAGES:
        if stages is not None and name not in stages:
            continue
        t0 = time.perf_counter()
        try:
            msg, status = fn(ctx), "done"
        except StageSkipped as exc:
            msg, status = f"skipped: {exc}", "skipped"
        except Exception as exc:  # a broken stage is reported, the job goes on
            msg, status = f"failed: {type(exc).__name__}: {exc}", "failed"
            ctx.section(f"Stage '{name}' failed", f"<pre>{esc(traceback.format_exc())}</pre>")
        rows.append({"stage": name, "status": status, "message": msg, "seconds": time.perf_counter() - t0})
        log.log(
            logging.WARNING if status == "failed" else logging.INFO,
            "[%7s] %s (%.1f s): %s",
            status,
            name,
            rows[-1]["seconds"],
            msg,
        )
    seconds = time.perf_counter() - t_all
    path = _write_report(ctx, rows, seconds)
    log.info("main job finished in %s", _minutes(seconds))
    for what, why, cmd in ctx.left:
        log.info("not recomputed: %s (%s): %s", what, why, cmd)
    return {
        "stages": rows,
        "report": str(path),
        "seconds": seconds,
        **floor_counts(ctx),
        "left": [{"what": w, "why": y, "command": c} for w, y, c in ctx.left],
    }
