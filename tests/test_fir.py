"""``fir``: least-squares FIR against the closed-form least squares, taps chosen on a hold-out, persistence, the
identify CLI and its bad input."""

import json
import time

import numpy as np
import pytest

from benchmarks.cli import main
from sysid.base import load_model
from sysid.data.io import write_record
from sysid.data.record import Record
from sysid.linear.fir import FIR, tap_grid
from tests._modal import modal_records, write_modal_pair


def _lstsq_fir(u, y, nb, nk):
    """Closed form: ordinary least squares on the lagged input columns, t ≥ nk + nb − 1 (numpy lstsq)."""
    N, m = u.shape
    L = nk + nb - 1
    Phi = np.column_stack([u[L - nk - k : N - nk - k, i] for i in range(m) for k in range(nb)])
    return np.linalg.lstsq(Phi, y[L:], rcond=None)[0].T.reshape(y.shape[1], m, nb)


def test_two_inputs_two_outputs_equal_the_closed_form_least_squares():
    rng = np.random.default_rng(0)
    N = 3000
    u = rng.standard_normal((N, 2))
    y = np.column_stack(
        [
            np.convolve(u[:, 0], [0.0, 1.0, 0.5, 0.2])[:N] + np.convolve(u[:, 1], [0, 0, -0.3, 0.1])[:N],
            u[:, 1] - 0.4 * np.r_[0.0, u[:-1, 0]],
        ]
    )
    y = y + 0.01 * rng.standard_normal(y.shape)
    for nb, nk in ((7, 1), (12, 0), (3, 2)):
        m = FIR(nb=nb, nk=nk).fit(Record(u, y, fs=1.0))
        np.testing.assert_allclose(m.taps_, _lstsq_fir(u, y, nb, nk), atol=1e-8)
        assert m.max_lag_ == nb + nk - 1 and m.n_parameters_ == 2 * 2 * nb and m.chosen_orders_ == {}


def test_prediction_is_the_convolution_with_the_taps_at_every_horizon():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(2000)
    h = 0.8 ** np.arange(30)
    y = np.convolve(u, np.r_[0.0, 0.0, h])[:2000] + 0.01 * rng.standard_normal(2000)
    rec = Record(u, y, fs=50.0)
    m = FIR(nb=30, nk=2).fit(rec)
    expect = np.convolve(u, np.r_[0.0, 0.0, m.taps_[0, 0]])[:2000]
    for horizon in (1, 5, None):
        yh = m.predict(rec, horizon)
        np.testing.assert_allclose(yh[m.max_lag_ :], expect[m.max_lag_ :], rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(yh[: m.max_lag_], y[: m.max_lag_])
    np.testing.assert_allclose(m.impulse_response()[2:], h, atol=0.01)  # the true impulse response


def test_taps_chosen_on_the_hold_out_reach_the_true_length():
    """True impulse response: 40 taps of comparable size, then nothing; 1 % noise. The hold-out choice is the first
    grid point at or beyond 40 taps, and the taps are the true ones."""
    rng = np.random.default_rng(2)
    h = np.cos(0.3 * np.arange(40)) * (1.0 + 0.5 * rng.random(40))
    u = rng.standard_normal(6000)
    y0 = np.convolve(u, h)[:6000]
    rec = Record(u, y0 + 0.01 * np.std(y0) * rng.standard_normal(6000), fs=1.0)
    m = FIR().fit(rec)
    first_past_40 = min(n for n in tap_grid(10_000) if n >= 40)
    assert m.chosen_orders_ == {"nb": first_past_40} and m.nb_ == first_past_40
    np.testing.assert_allclose(m.taps_[0, 0, :40], h, atol=0.01)
    np.testing.assert_allclose(m.taps_[0, 0, 40:], 0.0, atol=0.01)
    rows = m.describe()["order_selection"]
    assert [r["order"] for r in rows] == sorted(r["order"] for r in rows) and sum(r["chosen"] for r in rows) == 1
    assert m.describe()["order_search"]["corner"] is False


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_saved_model_predicts_identically(tmp_path, suffix):
    est, val = modal_records(n=2048)
    m = FIR().fit(est)
    m2 = load_model(m.save(tmp_path / f"fir{suffix}"))
    np.testing.assert_array_equal(m2.predict(val, None), m.predict(val, None))
    assert m2.chosen_orders_ == m.chosen_orders_ and m2.describe()["taps"] == m.describe()["taps"]


def test_identify_fir_json_has_the_taps_and_bad_tap_count_is_one_line(tmp_path, capsys):
    est_path, val_path = write_modal_pair(tmp_path, n=2048)
    assert main(["identify", "fir", "--est", est_path, "--val", val_path, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["identifier"] == "fir" and len(out["taps"]) == out["chosen_orders"]["nb"] == out["n_parameters"]
    assert out["validation"]["free_run"]["r2"] == out["validation"]["one_step"]["r2"] > 0.8
    for sets, words in (
        ("nb=5000", "too few for a FIR with nb=5000"),
        ("nb=0", "nb must be an integer >= 1"),
        ("nk=-1", "nk must be an integer >= 0"),
    ):
        assert main(["identify", "fir", "--est", est_path, "--set", sets]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.slow
def test_long_record_many_taps_in_seconds():
    """73 728 samples (the size of a ground-vibration record), taps chosen up to 2048: well under a minute."""
    est, val = modal_records(n=73728, fs=400.0, band=(2.0, 60.0), freqs=(5.3, 7.1, 13.0, 21.0, 33.0))
    t0 = time.perf_counter()
    m = FIR().fit(est)
    assert time.perf_counter() - t0 < 30.0
    assert m.nb_ >= 500 and m.score(val) > 0.9


def test_compare_shows_the_fir_reference_beside_the_models(tmp_path, capsys):
    est, val = modal_records(n=2048)
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    assert (
        main(
            [
                "identify",
                "arx",
                "--est",
                str(tmp_path / "est.npz"),
                "--set",
                "ny=2,nu=2",
                "-o",
                str(tmp_path / "arx.json"),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert (
        main(
            [
                "compare",
                str(tmp_path / "arx.json"),
                "--data",
                str(tmp_path / "val.npz"),
                "--fir-est",
                str(tmp_path / "est.npz"),
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    arx_row, fir_row = out["models"]
    assert fir_row["identifier"] == "fir" and fir_row["reference"] is True and "reference" not in arx_row
    fir = FIR().fit(est)  # the same FIR as identify fir's defaults; every row scored after its taps
    assert arx_row["skip"] == fir_row["skip"] == fir.max_lag_
    yh = fir.predict(val, None)[fir.max_lag_ :]
    y = val.y[fir.max_lag_ :]
    assert fir_row["metrics"]["r2"] == pytest.approx(1 - np.sum((y - yh) ** 2) / np.sum((y - y.mean()) ** 2), rel=1e-9)
    assert fir_row["metrics"]["r2"] > arx_row["metrics"]["r2"]  # ARX(2, 2) cannot simulate five light modes
    assert (
        main(
            [
                "compare",
                str(tmp_path / "arx.json"),
                "--data",
                str(tmp_path / "val.npz"),
                "--fir-est",
                str(tmp_path / "est.npz"),
            ]
        )
        == 0
    )
    assert "fir (reference" in capsys.readouterr().out


def test_band_limited_input_taps_stay_near_the_true_impulse_response():
    """A multisine over 3–300 Hz at 1 kHz leaves 300–500 Hz unexcited: plain least squares fills it with large
    cancelling taps, the default ridge (chosen on the hold-out) keeps the taps near the modes' true impulse response
    (scipy.signal.lfilter of the modal filters) at the same validation R²."""
    from scipy import signal

    from tests._modal import modal_filters

    est, val = modal_records()
    m = FIR().fit(est)
    imp = np.zeros(m.nb_)
    imp[0] = 1.0
    h0 = sum(signal.lfilter(b, a, imp) for b, a in modal_filters(1000.0))
    h = m.taps_[0, 0]
    assert m.ridge_ > 1e-6 and any(r["chosen"] for r in m.order_search_["ridge_selection"])
    assert np.max(np.abs(h)) < 1.5 * np.max(np.abs(h0)) and np.argmax(np.abs(h)) == np.argmax(np.abs(h0))
    assert np.linalg.norm(h - h0) < 0.6 * np.linalg.norm(h0)
    plain = FIR(nb=m.nb_, ridge=0).fit(est)
    assert np.max(np.abs(plain.taps_)) > 100 * np.max(np.abs(h0))
    assert abs(m.score(val) - plain.score(val)) < 1e-3
