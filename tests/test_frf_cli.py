"""Frequency domain end to end: the frf / bla commands on the cantilever twin and the
Wiener-Hammerstein benchmark, checked against the twin's exact linear FRF and the published BLA RMSE."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.cli import main
from sysid.data.io import read_record
from twins.cantilever import CantileverTwin

LINEAR = ["--set", "hysteresis=prandtl-ishlinskii,pi_p0_fraction=1"]  # Γ = d·v: the hysteresis switched off
PERIODS = 3


def _cli(args, capsys):
    capsys.readouterr()  # drop what earlier commands printed
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Three random-phase odd multisines (2 Hz grid up to 500 Hz, 10 % odd detection lines, 80 V peak,
    3 periods at 10 kHz), made with ``piezotwin signal``."""
    d = tmp_path_factory.mktemp("ms")
    paths = []
    for seed in (1, 2, 3):
        p = d / f"u{seed}.npz"
        assert (
            main(
                [
                    "signal",
                    "multisine",
                    "--fs",
                    "10000",
                    "--resolution",
                    "2",
                    "--band",
                    "2:500",
                    "--grid",
                    "odd",
                    "--detection-fraction",
                    "0.1",
                    "--periods",
                    str(PERIODS),
                    "--amplitude",
                    "80",
                    "--seed",
                    str(seed),
                    "-o",
                    str(p),
                ]
            )
            == 0
        )
        paths.append(p)
    return paths


def _simulate(inputs, tmp_path, tag, twin_args):
    out = []
    for i, u in enumerate(inputs):
        p = tmp_path / f"{tag}{i}.npz"
        assert main(["simulate", "cantilever", "--input", str(u), *twin_args, "-o", str(p)]) == 0
        out.append(p)
    return out


def test_sampled_frf_agrees_with_the_continuous_model():
    """Independent check of the exact sampled FRF against the continuous model d·(1 + Σ g/(jωτ_i + 1))·D(jω)·
    sensor(jω): a first-order hold between samples multiplies it by sinc²(f/fs) (no phase), and at
    fs = 100 kHz the aliases of a system that rolls off above 5 kHz are negligible."""
    f = np.array([0.5, 10.0, 100.0, 500.0, 700.0, 2000.0])
    fs = 1e5
    for effects in ([], ["second_mode", "sensor_lowpass", "creep"]):
        tw = CantileverTwin(effects=effects)
        p = tw.params
        creep = (
            1.0 + sum(p.creep_per_decade / (2j * np.pi * f * tau + 1.0) for tau in tw.creep_taus())
            if "creep" in effects
            else 1.0
        )
        Hc = p.gain_um_per_v * creep * tw.frequency_response(f) * np.sinc(f / fs) ** 2
        Hd = tw.sampled_frequency_response(f, fs)
        assert np.allclose(Hd, Hc, rtol=1e-3)


def test_frf_matches_the_exact_linear_frf_of_the_cantilever(inputs, tmp_path, capsys):
    """Done when: --effects none, hysteresis disabled → multisine FRF within 0.5 dB / 3° at the excited lines."""
    (y,) = _simulate(inputs[:1], tmp_path, "lin", ["--effects", "none", *LINEAR])
    code, out, _ = _cli(
        [
            "frf",
            y,
            "--periods",
            PERIODS,
            "--drop",
            1,
            "--json",
            "-o",
            tmp_path / "frf.csv",
            "--plot",
            tmp_path / "frf.png",
        ],
        capsys,
    )
    assert code == 0
    res = json.loads(out)
    assert set(res) >= {"f_hz", "re", "im", "std"}
    G = np.array(res["re"]) + 1j * np.array(res["im"])
    f = np.array(res["f_hz"])
    rec = read_record(y)
    exact = (
        CantileverTwin(effects=[])
        .with_params(hysteresis="prandtl-ishlinskii", pi_p0_fraction=1.0)
        .sampled_frequency_response(f, rec.fs)
    )
    bins = np.array(rec.meta["signal"]["info"]["excited_bins"])
    assert np.allclose(f, bins * 2.0)  # exactly the excited lines
    assert np.max(np.abs(20 * np.log10(np.abs(G / exact)))) < 0.5
    assert np.max(np.abs(np.degrees(np.angle(G / exact)))) < 3.0
    csv = np.genfromtxt(tmp_path / "frf.csv", delimiter=",", names=True)
    assert csv.dtype.names == ("f_hz", "re", "im", "mag_db", "phase_deg", "std")
    assert np.allclose(csv["re"], G.real)
    assert (tmp_path / "frf.png").stat().st_size > 1000


def test_frf_h1_json_has_coherence(inputs, tmp_path, capsys):
    (y,) = _simulate(inputs[:1], tmp_path, "noisy", ["--effects", "measurement_noise", *LINEAR])
    code, out, _ = _cli(["frf", y, "--json", "--nperseg", 5000], capsys)
    assert code == 0
    res = json.loads(out)
    assert set(res) >= {"f_hz", "re", "im", "coherence"} and "std" not in res
    coh = np.array([np.nan if c is None else c for c in res["coherence"]])
    # one Welch segment = one period (5000 samples): the excited lines are Welch bins, with coherence ~1;
    # the lines the odd multisine leaves empty have none (nothing but noise and leakage there)
    bins = np.array(read_record(y).meta["signal"]["info"]["excited_bins"])
    assert np.allclose(np.array(res["f_hz"])[bins], bins * 2.0)
    assert np.min(coh[bins]) > 0.99


def test_frf_bad_periods_exit_2(inputs, tmp_path, capsys):
    (y,) = _simulate(inputs[:1], tmp_path, "bad", ["--effects", "none"])
    code, _, err = _cli(["frf", y, "--periods", 7], capsys)
    assert code == 2 and "periods" in err and "Traceback" not in err


@pytest.mark.parametrize(
    "tag, twin_args, verdict",
    [
        ("linear", ["--effects", "measurement_noise", *LINEAR], "linear"),
        ("hysteresis", ["--effects", "measurement_noise"], "odd"),  # Bouc–Wen: odd-symmetric loop
        ("asymmetric", ["--effects", "measurement_noise,asymmetric_hysteresis"], "odd+even"),
        ("drift", ["--effects", "measurement_noise,thermal_drift", *LINEAR], "linear"),  # drift removed (--detrend 1)
        (
            "saturation",
            ["--effects", "measurement_noise,saturation", *LINEAR, "--set", "sat_voltage_v=60"],
            "odd",
        ),  # odd-symmetric compression of the amplifier, hysteresis off
    ],
)
def test_bla_detects_the_cantilever_nonlinearity(inputs, tmp_path, capsys, tag, twin_args, verdict):
    """Done when: 'linear' on a linear configuration, odd distortion with the hysteresis, even distortion as
    well with the asymmetric hysteresis (the catalog's even effect), levels in dB."""
    ys = _simulate(inputs, tmp_path, tag, twin_args)
    code, out, _ = _cli(["bla", *ys, "--periods", PERIODS, "--drop", 1, "--json"], capsys)
    assert code == 0
    res = json.loads(out)
    assert set(res) >= {"f_hz", "re", "im", "var_noise", "var_distortion", "nonlinearity"}
    nl = res["nonlinearity"]
    assert nl["verdict"] == verdict
    assert isinstance(nl["odd_db"], float) and isinstance(nl["even_db"], float)
    if "odd" in verdict:
        assert nl["odd_db"] > 30  # measured 56 dB (Bouc-Wen at 80 V against 5 nm noise)
    if "even" in verdict:
        assert nl["even_db"] > 20  # measured 45 dB
    if verdict == "linear" and tag == "drift":  # without the drift removal the drift looks like distortion
        code, out, _ = _cli(["bla", *ys, "--periods", PERIODS, "--drop", 1, "--detrend", 0, "--json"], capsys)
        assert json.loads(out)["nonlinearity"]["verdict"] != "linear"
    elif verdict == "linear":  # and G_BLA is the exact linear FRF within the noise
        G = np.array(res["re"]) + 1j * np.array(res["im"])
        exact = (
            CantileverTwin(effects=[])
            .with_params(hysteresis="prandtl-ishlinskii", pi_p0_fraction=1.0)
            .sampled_frequency_response(np.array(res["f_hz"]), 1e4)
        )
        assert np.max(np.abs(20 * np.log10(np.abs(G / exact)))) < 0.05
        code, out, _ = _cli(["bla", *ys, "--periods", PERIODS, "--drop", 1, "--plot", tmp_path / "bla.png"], capsys)
        assert code == 0 and "verdict linear" in out and (tmp_path / "bla.png").stat().st_size > 1000
    else:  # the realisations disagree: distortion variance far above the noise variance
        assert np.median(res["var_distortion"]) > 100 * np.median(res["var_noise"])


def test_wiener_hammerstein_bla_reaches_the_published_rmse():
    """Done when: a BLA-based linear simulation on the WH benchmark test set reaches the published BLA free-run
    RMSE 44.4 mV within 10 %. H1 FRF of the estimation data (Welch, 1024 samples, Hann), 6/6 discrete
    transfer function fitted with input-spectrum weights (output-error criterion), offsets from the
    estimation means; scored from sample 50 (the benchmark's initialisation window)."""
    import scipy.signal as ss

    from benchmarks.datasets import load_dataset
    from sysid.linear.frf import frf_welch
    from sysid.linear.tfest import tfest

    ds = load_dataset("wiener-hammerstein")
    est, test = ds.est, ds.tests["test"]
    frf = frf_welch(est.u, est.y, est.fs, nperseg=1024)
    _, suu = ss.welch(est.u, fs=est.fs, nperseg=1024)
    tf = tfest(frf.f_hz, frf.G, est.fs, nb=6, na=6, weight=suu)
    y_hat = tf.simulate(test.u - est.u.mean()) + est.y.mean()
    rmse = float(np.sqrt(np.mean((test.y - y_hat)[ds.init_samples :] ** 2)))
    published = ds.references["test"]["linear_baseline"]["value"]
    assert published == pytest.approx(44.4e-3)
    assert rmse < 1.10 * published  # measured 43.3 mV
    assert np.all(np.abs(tf.poles) < 1)


def test_wiener_hammerstein_bla_identifier():
    """The registered ``bla`` identifier (what ``score`` runs) does the same with its defaults."""
    from benchmarks.datasets import load_dataset
    from sysid.registry import get_identifier

    ds = load_dataset("wiener-hammerstein")
    model = get_identifier("bla")().fit(ds.est)
    test = ds.tests["test"]
    rmse = float(np.sqrt(np.mean((test.y - model.predict(test, horizon=None))[ds.init_samples :] ** 2)))
    assert rmse < 1.10 * ds.references["test"]["linear_baseline"]["value"]  # measured 43.3 mV


def test_bla_bad_input_exit_2(inputs, tmp_path, capsys):
    (y,) = _simulate(inputs[:1], tmp_path, "b", ["--effects", "none"])
    short = tmp_path / "short.npz"
    rec = read_record(y)
    from sysid.data.io import write_record

    write_record(rec[: len(rec) // 3 * 2], short)
    for args in (
        ["bla", y, "--periods", 3, "--drop", 3],
        ["bla", y, short, "--periods", 3],
        ["bla", tmp_path / "missing.npz", "--periods", 3],
        ["bla", y, "--periods", 3, "--alpha", 2],
    ):
        code, _, err = _cli(args, capsys)
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary file left behind
