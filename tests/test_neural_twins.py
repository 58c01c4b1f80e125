"""The neural identifiers on the twins. Fast reduced-budget variants run by default; the
full-budget figures of the README are the slow tests."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("twins.cantilever")

from benchmarks.neural_twins import cantilever_data, cantilever_sines  # noqa: E402

TABLE_4_3_MIN = 0.986  # dissertation Table 4.3: FRS R² 0.986–0.998 over the sines (4 × 25 ReLU, lags 10)


def test_cantilever_reduced_budget_sim_training():
    """1.5 s of thesis-multisine (15 000 samples), three sines, a few epochs of simulation-error training of
    the dissertation's network: free-run R² on every sine ≥ 0.97."""
    data = cantilever_data(duration_s=1.5, freqs_hz=(10.0, 100.0, 300.0))
    res = cantilever_sines("narx-mlp-sim", {"epochs": 2, "pretrain_epochs": 15, "batch_size": 32}, seed=0, data=data)
    assert res["n_parameters"] == 2501
    assert min(res["r2_per_freq"].values()) >= 0.97, res["r2_per_freq"]


@pytest.mark.slow
def test_cantilever_table_4_3_full_budget_one_step():
    """Table 4.1 training (100 epochs, lr 1e-4, batch 128, one-step) on the full 80 000-sample multisine, all
    twelve sines 0.1–500 Hz, three seeds: mean free-run R² over the sines ≥ 0.98 (measured 0.981 ± 0.006 over
    seeds 0-2)."""
    data = cantilever_data()
    means = [cantilever_sines("narx-mlp", {}, seed=s, data=data)["r2_mean"] for s in (0, 1, 2)]
    assert np.mean(means) >= 0.98, means


@pytest.mark.slow
def test_cantilever_full_budget_sim_training():
    """Simulation-error training of the same network: mean free-run R² over the twelve sines ≥ 0.986 (the
    lower end of Table 4.3)."""
    data = cantilever_data()
    res = cantilever_sines(
        "narx-mlp-sim",
        {"epochs": 10, "pretrain_epochs": 20, "window": 50, "batch_size": 16, "lr": 3e-4},
        seed=0,
        data=data,
    )
    assert res["r2_mean"] >= TABLE_4_3_MIN, res["r2_per_freq"]


@pytest.mark.slow
def test_acoustic_table_5_6_analogue():
    """Dissertation's best acoustic network (lags 512, 2 × 75 sigmoid, 75 epochs, one-step) on the twin's
    preprocessed multisine → 1 ms chirp, 5 seeds: estimation free-run R² ≥ 0.98 on average for one-step
    training (Fig. 5.13a: 0.997 ± 0.001; measured 0.991) and one-step validation R² ≥ 0.85 (Table 5.6:
    0.88–0.91; measured 0.867–0.900). The simulation-error fine-tuning trades estimation fit for validation
    (measured estimation free-run 0.76–0.98, mean 0.89): ≥ 0.85 on average."""
    pytest.importorskip("twins.acoustic")
    from benchmarks.neural_twins import acoustic_data, acoustic_osa_vs_sim

    res = acoustic_osa_vs_sim(seeds=(0, 1, 2, 3, 4), data=acoustic_data())
    runs = res["runs"]
    assert np.mean([r["osa_r2_est_frs"] for r in runs]) >= 0.98
    assert np.mean([r["sim_r2_est_frs"] for r in runs]) >= 0.85
    assert np.mean([r["osa_r2_val_osa"] for r in runs]) >= 0.85


def _sim_beats_one_step(res, n):
    assert res["sim_wins"] == n and res["sim_r2_val_frs_mean"] > res["osa_r2_val_frs_mean"], res
    for r in res["runs"]:  # warm start: the one-step model is the simulation-error run's starting point
        assert r["sim_r2_val_frs"] > r["osa_r2_val_frs"], r


@pytest.mark.slow
@pytest.mark.parametrize("nk", [1, 450])
def test_acoustic_sim_training_beats_one_step_on_chirp_validation(nk):
    """Multisine → 1 ms chirp, 5 seeds, the same network and data for both trainings: simulation-error
    fine-tuning of the one-step model beats the one-step model in validation free-run R² for every seed.
    Measured: nk=1 (eq. 2-14) one-step −0.33 ± 0.21, simulation error −0.26 ± 0.22; nk=450 (≈ time of
    flight) one-step 0.690 ± 0.025, simulation error 0.749 ± 0.028 (dissertation Fig. 5.13: 0.548 ± 0.053)."""
    pytest.importorskip("twins.acoustic")
    from benchmarks.neural_twins import acoustic_data, acoustic_osa_vs_sim

    res = acoustic_osa_vs_sim(seeds=(0, 1, 2, 3, 4), structure={"nk": nk}, data=acoustic_data())
    _sim_beats_one_step(res, 5)
    if nk == 450:
        assert res["sim_r2_val_frs_mean"] > 0.548 + 0.053, res  # above the dissertation's 0.548 ± 0.053


def test_acoustic_sim_training_beats_one_step_reduced():
    """Fast variant (one seed, input delay at the time of flight): measured 0.724 → 0.752."""
    pytest.importorskip("twins.acoustic")
    from benchmarks.neural_twins import ACOUSTIC_NK, acoustic_data, acoustic_osa_vs_sim

    res = acoustic_osa_vs_sim(seeds=(0,), structure={"nk": ACOUSTIC_NK}, data=acoustic_data())
    _sim_beats_one_step(res, 1)
