"""Dataset registry: every dataset loads with the shapes, rates, splits and windows of its published description."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from benchmarks.datasets import Dataset, dataset_names, lab, list_datasets, load_dataset
from benchmarks.datasets import twin as twin_ds
from sysid.errors import ConfigError, DataError, InputError

REPO = Path(__file__).resolve().parents[1]


def _shared_data() -> Path | None:
    for cand in (
        os.environ.get("PIEZOTWIN_SHARED_DATA"),
        REPO.parent / "shared" / "data",
        REPO.parents[1] / "shared" / "data",
    ):
        if cand and Path(cand).is_dir():
            return Path(cand)
    return None


# Published descriptions (SOURCE.txt of each dataset and the benchmark papers):
# name -> (fs [Hz], estimation samples, {test: samples}, init window, units)
PUBLISHED = {
    "silverbox": (
        610.35,
        105712 - 40650,
        {"multisine": 127400 - 105712, "arrow": 40575 - 100, "arrow-no-extrapolation": 32000},
        50,
        ("V", "V"),
    ),
    "wiener-hammerstein": (51200.0, 100000, {"test": 88000, "test-official": 184000 - 105200}, 50, ("V", "V")),
    "cascaded-tanks": (0.25, 1024, {"test": 1024, "test-official": 1024}, 4, ("V", "V")),
    "bouc-wen": (750.0, 40960, {"multisine": 8192, "sinesweep": 153000}, 0, ("N", "m")),
    "piezo-tue": (5000.0, 25000, {"test": 25001}, 0, ("V", "um")),
}


@pytest.mark.parametrize("name", list(PUBLISHED))
def test_lab_dataset_matches_published_description(name):
    fs, n_est, tests, init, units = PUBLISHED[name]
    ds = load_dataset(name)
    assert isinstance(ds, Dataset) and ds.kind == "lab"
    assert ds.fs == pytest.approx(fs, rel=1e-12)
    assert len(ds.est) == n_est
    assert {k: len(v) for k, v in ds.tests.items()} == tests
    assert ds.init_samples == init
    assert (ds.units["u"], ds.units["y"]) == units
    for rec in [ds.est, *ds.tests.values()]:
        assert rec.u.dtype == np.float64 and rec.y.dtype == np.float64
        assert rec.u.ndim == 1 and rec.y.ndim == 1 and np.isfinite(rec.u).all() and np.isfinite(rec.y).all()
        assert rec.fs == ds.fs


def test_raw_record_lengths_and_ranges():
    """Whole-record sizes and signal ranges stated in the SOURCE files."""
    sb = lab.read_vendored("silverbox")["SNLS80mV"]
    assert len(sb) == 131072
    wh = lab.read_vendored("wiener-hammerstein")["WienerHammerBenchmark"]
    assert len(wh) == 188000
    assert -3.1 < wh.u.min() < -2.9 and 2.8 < wh.u.max() < 3.0 and -1.2 < wh.y.min() < -1.0 and 0.6 < wh.y.max() < 0.7
    bw = lab.read_vendored("bouc-wen")
    ms = bw["test_multisine"]
    assert -205 < ms.u.min() < -195 and 165 < ms.u.max() < 171  # "u approx -202..168"
    assert 2.0e-3 < np.abs(ms.y).max() < 2.6e-3  # "y approx +/-2.3e-3"
    # the generated training multisine is 5 periods of 8192 samples of the same input
    tr = bw["train"].u
    assert np.array_equal(tr[:8192], tr[8192:16384])
    pz = lab.read_vendored("piezo-tue")["hysteresis_v_150_1hz"]
    assert len(pz) == 50001
    assert 149 < np.abs(pz.u).max() <= 150.5 and 19 < np.abs(pz.y).max() < 20.5  # 150 V, approx +/-19.7 um
    ct = load_dataset("cascaded-tanks")
    assert 0 < ct.est.y.min() and ct.est.y.max() < 11  # tank level sensor in V


def test_splits_are_the_official_sample_ranges():
    sb = lab.read_vendored("silverbox")["SNLS80mV"]
    ds = load_dataset("silverbox")
    assert np.array_equal(ds.est.u, sb.u[40650:105712])
    assert np.array_equal(ds.tests["multisine"].y, sb.y[105712:127400])
    assert np.array_equal(ds.tests["arrow"].u, sb.u[100:40575])
    wh = load_dataset("wiener-hammerstein")
    raw = lab.read_vendored("wiener-hammerstein")["WienerHammerBenchmark"]
    assert np.array_equal(np.concatenate([wh.est.y, wh.tests["test"].y]), raw.y)
    assert wh.tests["test"].meta["split"]["start"] == 100000


def test_references_attached():
    sb = load_dataset("silverbox")
    assert sb.references["multisine"]["sysidentpy"]["value"] == pytest.approx(7.73e-3)
    assert sb.references["arrow"]["sysidentpy"]["value"] == pytest.approx(4.15e-3)
    wh = load_dataset("wiener-hammerstein")
    assert wh.references["test"]["linear_baseline"]["value"] == pytest.approx(44.4e-3)
    ct = load_dataset("cascaded-tanks")
    assert ct.references["test"]["linear_baseline"]["value"] == pytest.approx(0.75)


def test_vendored_files_carry_source_licence_and_provenance():
    for spec in lab.LAB_SPECS.values():
        folder = lab.DATA_DIR / spec.folder
        names = {p.name for p in folder.iterdir()}
        assert "SOURCE.txt" in names and "PROVENANCE.txt" in names
        assert any(n.upper().startswith("LICENSE") for n in names), spec.folder
        prov = (folder / "PROVENANCE.txt").read_text()
        for orig in spec.originals:
            assert orig in prov
        # plain numpy can read them without pickle
        for stem in spec.records:
            with np.load(folder / f"{stem}.npz", allow_pickle=False) as z:
                assert z["u"].dtype == np.float64


@pytest.mark.parametrize("name", list(lab.LAB_SPECS))
def test_original_files_give_identical_dataset(name):
    """The loader accepts the original published files, and the vendored copy is bit-identical to them."""
    shared = _shared_data()
    if shared is None:
        pytest.skip("original files (../shared/data or $PIEZOTWIN_SHARED_DATA) not available")
    src = shared / lab.LAB_SPECS[name].folder
    a, b = load_dataset(name), load_dataset(name, source=src)
    assert np.array_equal(a.est.u, b.est.u) and np.array_equal(a.est.y, b.est.y)
    for t in a.tests:
        assert np.array_equal(a.tests[t].u, b.tests[t].u) and np.array_equal(a.tests[t].y, b.tests[t].y)
    import hashlib

    prov = (lab.DATA_DIR / lab.LAB_SPECS[name].folder / "PROVENANCE.txt").read_text()
    for orig in lab.LAB_SPECS[name].originals:
        assert hashlib.sha256((src / orig).read_bytes()).hexdigest() in prov


def test_original_csv_of_a_user(tmp_path):
    """A user's own copy of a published CSV (Cascaded Tanks layout) loads with the official split."""
    n = 1024
    rng = np.random.default_rng(0)
    cols = rng.normal(size=(n, 4))
    lines = ['"uEst","uVal","yEst","yVal","Ts",']
    for i in range(n):
        row = [repr(float(v)) for v in cols[i]] + (["4"] if i == 0 else [""])
        lines.append(",".join(row) + ",")
    (tmp_path / "dataBenchmark.csv").write_text("\n".join(lines) + "\n")
    ds = load_dataset("cascaded-tanks", source=tmp_path)
    assert np.array_equal(ds.est.u, cols[:, 0]) and np.array_equal(ds.tests["test"].y, cols[:, 3])
    assert ds.fs == 0.25


def test_bad_names_and_sources():
    with pytest.raises(ConfigError, match="unknown dataset"):
        load_dataset("nosuch")
    with pytest.raises(DataError, match="not found"):
        load_dataset("silverbox", source="/nonexistent/dir")
    with pytest.raises(InputError):
        load_dataset("piezo-tue", source=REPO / "README.md")


def test_list_datasets_describes_all():
    rows = list_datasets()
    assert [r["id"] for r in rows] == dataset_names()
    for r in rows:
        assert {"id", "kind", "fs_hz", "tests", "init_samples", "available", "description"} <= set(r)


# ----------------------------------------------------------------------------- twin datasets (cache logic)
class _FakeTwin:
    """Minimal stand-in with the Twin interface the dataset generator uses (counts generate calls)."""

    name = "fake"
    EFFECTS = {"measurement_noise": None, "other": None}
    calls = 0

    def __init__(self, params, effects, seed):
        self.effects, self.seed = frozenset(effects), seed

    @classmethod
    def default_effects(cls):
        return frozenset({"measurement_noise", "other"})

    def config(self):
        return {"twin": "fake", "params": {}, "effects": sorted(self.effects), "seed": self.seed}

    def check_protocol(self, p):
        if p not in ("a", "b"):
            raise ConfigError(p)

    def generate(self, protocol, **opts):
        from sysid.data.record import Record

        type(self).calls += 1
        rng = np.random.default_rng(self.seed)
        u = np.sin(np.arange(200) * (0.1 if protocol == "a" else 0.3))
        y = 2 * u + (0.01 * rng.normal(size=u.size) if "measurement_noise" in self.effects else 0.0)
        return Record(u=u, y=y, fs=100.0, units={"u": "V", "y": "um"})


def test_twin_dataset_generated_cached_and_noise_switch(tmp_path, monkeypatch):
    import twins.registry

    monkeypatch.setenv("PIEZOTWIN_CACHE", str(tmp_path))
    monkeypatch.setattr(twins.registry, "get_twin", lambda name: _FakeTwin)
    spec = twin_ds.TwinDatasetSpec(
        name="fake-ab",
        twin="fake",
        est=("a", {}),
        tests={"b": ("b", {})},
        noise=True,
        seed=3,
        fs=100.0,
        init_samples=0,
        description="fake",
    )
    clean = twin_ds.TwinDatasetSpec(
        name="fake-ab-clean",
        twin="fake",
        est=("a", {}),
        tests={"b": ("b", {})},
        noise=False,
        seed=3,
        fs=100.0,
        init_samples=0,
        description="fake",
    )
    monkeypatch.setitem(twin_ds.TWIN_DATASETS, "fake-ab", spec)
    monkeypatch.setitem(twin_ds.TWIN_DATASETS, "fake-ab-clean", clean)
    _FakeTwin.calls = 0
    d1 = load_dataset("fake-ab")
    assert _FakeTwin.calls == 2 and d1.kind == "twin" and set(d1.tests) == {"b"}
    d2 = load_dataset("fake-ab")  # from the cache: no new generation, identical data
    assert _FakeTwin.calls == 2
    assert np.array_equal(d1.est.y, d2.est.y) and d2.units["y"] == "um"
    assert Path(d2.meta["cache"]).parent == tmp_path / "datasets"
    c = load_dataset("fake-ab-clean")
    assert _FakeTwin.calls == 4
    assert np.array_equal(c.est.y, 2 * c.est.u) and not np.array_equal(d1.est.y, c.est.y)
    assert d1.meta["cache"] != c.meta["cache"]


def test_twin_dataset_unavailable_twin_is_a_clear_error(monkeypatch):
    import twins.registry

    def nope(name):
        raise ConfigError(f"twin {name!r} is not available in this build")

    monkeypatch.setattr(twins.registry, "get_twin", nope)
    with pytest.raises(ConfigError, match="needs the cantilever twin"):
        load_dataset("cantilever-thesis")


def _twin_built(name: str) -> bool:
    from twins.registry import available_twins

    return name in available_twins()


def test_cantilever_twin_dataset_follows_the_dissertation():
    """§3.1: thesis-multisine of 8 s at 10 kHz (80 000 samples) for estimation, the thesis sines for test."""
    if not _twin_built("cantilever"):
        pytest.skip("cantilever twin not built in this checkout")
    ds = load_dataset("cantilever-thesis")
    assert ds.fs == 10_000.0 and len(ds.est) == 80_000 and ds.units["y"] in ("um", "µm")
    freqs = [s.meta["segment"]["freq_hz"] for s in ds.tests["thesis-sines"].segments()]
    assert freqs == [0.1, 1.0, 10.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 400.0, 450.0, 500.0]
    assert np.max(np.abs(ds.est.u)) == pytest.approx(100.0)  # ±100 V
    clean = load_dataset("cantilever-thesis-clean")
    assert np.array_equal(clean.est.u, ds.est.u) and not np.array_equal(clean.est.y, ds.est.y)
    assert "measurement_noise" in ds.est.meta["effects"] and "measurement_noise" not in clean.est.meta["effects"]


def test_acoustic_twin_dataset_is_preprocessed():
    """§3.2: multisine → 1 ms chirp, after the moving average / resampling to 6.75 MHz / band-pass recipe."""
    if not _twin_built("acoustic"):
        pytest.skip("acoustic twin not built in this checkout")
    ds = load_dataset("acoustic-thesis")
    assert ds.fs == pytest.approx(6.75e6) and len(ds.est) == 20_000
    assert len(ds.tests["thesis-chirp-1ms"]) == 6750  # one whole 1 ms sweep
    f = np.fft.rfftfreq(len(ds.est), 1 / ds.fs)
    p = np.abs(np.fft.rfft(ds.est.u)) ** 2
    assert p[(f > 900e3) & (f < 1350e3)].sum() > 0.9 * p.sum()  # the excitation lives in the band
