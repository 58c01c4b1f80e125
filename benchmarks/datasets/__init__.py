"""Dataset registry: the twins' dissertation datasets and recorded lab benchmarks (``piezotwin list datasets``).

``list_datasets()`` describes every dataset without loading it; ``load_dataset(name)`` returns a
:class:`Dataset` — estimation record(s), named test records, the initialisation window (samples at the start
of each test that free-run simulation may take from the measurement and that are not scored), units,
sampling rate and the published reference numbers.

Lab data come from compact copies vendored in ``benchmarks/data/`` (see :mod:`benchmarks.datasets.lab`);
``load_dataset(name, source=PATH)`` builds the same dataset from the original published files instead. Every
lab data file, with its licence and source note and the loader that reads it, is listed in
:mod:`benchmarks.datasets.files`; the twins compared with lab data receive the loaded records and arrays.
Twin datasets are generated on demand and cached (:mod:`benchmarks.datasets.twin`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchmarks.datasets import lab, twin
from benchmarks.datasets.references import references_for
from sysid.data.record import Record
from sysid.errors import ConfigError

__all__ = ["Dataset", "list_datasets", "load_dataset", "dataset_names", "LAB_DESCRIPTIONS"]


@dataclass
class Dataset:
    """One benchmark: estimation data, named test sets, the initialisation window and reference numbers.

    ``references[test][kind]`` holds published free-run RMSE values (``value`` in ``units['y']``, ``model``);
    ``init_samples`` is the initialisation window of the tests (Silverbox and Wiener–Hammerstein 50, Cascaded
    Tanks 4), ``test_init`` a test's own window where it differs (Cascaded Tanks ``test-official``: 50, the official
    dataloader's): scores of test T are computed from sample ``max(init_for(T), model.max_lag_)`` on.
    """

    name: str
    kind: str  # "lab" or "twin"
    description: str
    est: Record | list[Record]
    tests: dict[str, Record]
    init_samples: int
    fs: float
    units: dict[str, str]
    references: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    nonlinear: bool = True
    meta: dict[str, Any] = field(default_factory=dict)
    test_init: dict[str, int] = field(default_factory=dict)

    def init_for(self, test: str) -> int:
        """The initialisation window [samples] of test ``test``."""
        return int(self.test_init.get(test, self.init_samples))

    @property
    def est_records(self) -> list[Record]:
        return list(self.est) if isinstance(self.est, (list, tuple)) else [self.est]

    def summary(self) -> dict[str, Any]:
        return {
            "id": self.name,
            "kind": self.kind,
            "fs_hz": self.fs,
            "init_samples": self.init_samples,
            "test_init_samples": {t: self.init_for(t) for t in self.tests},
            "est_samples": sum(len(r) for r in self.est_records),
            "tests": {k: len(v) for k, v in self.tests.items()},
            "units": dict(self.units),
            "references": self.references,
            "description": self.description,
        }


LAB_DESCRIPTIONS = {
    "silverbox": "Silverbox (electronic Duffing oscillator, measured; Wigren & Schoukens 2013): multisine "
    "estimation, multisine and arrow (full / no extrapolation) tests",
    "wiener-hammerstein": "Wiener-Hammerstein 2009 benchmark (measured circuit): estimation samples 1-100000, "
    "test 100001-188000",
    "cascaded-tanks": "Cascaded Tanks (measured; Schoukens et al.): uEst/yEst estimation, uVal/yVal test, Ts 4 s",
    "bouc-wen": "Bouc-Wen hysteretic benchmark (simulated; Noel & Schoukens 2016): Forgione's generated training "
    "multisine, official multisine and sine-sweep tests",
    "piezo-tue": "measured piezo actuator (150 V, 1 Hz sine; Chandra et al. 2023): first 5 s estimation, last 5 s test",
}
_LAB_FS = {
    "silverbox": lab.SILVERBOX_FS_HZ,
    "wiener-hammerstein": lab.WH_FS_HZ,
    "cascaded-tanks": 1.0 / lab.CASCADED_TANKS_TS_S,
    "bouc-wen": lab.BOUC_WEN_FS_HZ,
    "piezo-tue": lab.PIEZO_TUE_FS_HZ,
}


def dataset_names() -> list[str]:
    return list(lab.LAB_SPECS) + list(twin.TWIN_DATASETS)


def _twin_available(name: str) -> tuple[bool, str]:
    from twins.registry import get_twin

    try:
        get_twin(name)
    except ConfigError as exc:
        return False, str(exc)
    return True, ""


def list_datasets() -> list[dict[str, Any]]:
    """Every registered dataset, described without loading it."""
    out = []
    for name in lab.LAB_SPECS:
        split = lab.SPLITS[name]
        out.append(
            {
                "id": name,
                "kind": "lab",
                "fs_hz": _LAB_FS[name],
                "est_samples": split["est"][2] - split["est"][1],
                "tests": {t: b - a for t, (_, a, b) in split["tests"].items()},
                "init_samples": lab.INIT_SAMPLES[name],
                "test_init_samples": {
                    t: lab.TEST_INIT_SAMPLES.get(name, {}).get(t, lab.INIT_SAMPLES[name]) for t in split["tests"]
                },
                "available": True,
                "description": LAB_DESCRIPTIONS[name],
            }
        )
    for name, spec in twin.TWIN_DATASETS.items():
        ok, why = _twin_available(spec.twin)
        out.append(
            {
                "id": name,
                "kind": "twin",
                "fs_hz": spec.fs,
                "est_samples": None,
                "tests": {t: None for t in spec.tests},
                "init_samples": spec.init_samples,
                "test_init_samples": {t: spec.init_samples for t in spec.tests},
                "available": ok,
                "description": spec.description + ("" if ok else f" [not available: {why}]"),
            }
        )
    return out


def load_dataset(
    name: str, source: str | Path | None = None, use_cache: bool = True, progress: bool = False
) -> Dataset:
    """The :class:`Dataset` registered as ``name``.

    ``source`` (lab datasets only): a folder (or file) with the original published files, read instead of the
    vendored copy. ``use_cache`` (twin datasets): reuse cached records; ``progress`` shows a tqdm bar while
    generating.
    """
    if name in lab.LAB_SPECS:
        raws = lab.read_original(name, source) if source is not None else lab.read_vendored(name)
        est, tests = lab.cut(raws, name)
        return Dataset(
            name=name,
            kind="lab",
            description=LAB_DESCRIPTIONS[name],
            est=est,
            tests=tests,
            init_samples=lab.INIT_SAMPLES[name],
            fs=est.fs,
            units=dict(est.units),
            references=references_for(name),
            nonlinear=True,
            test_init=dict(lab.TEST_INIT_SAMPLES.get(name, {})),
            meta={
                "source": str(source) if source is not None else f"benchmarks/data/{lab.LAB_SPECS[name].folder}",
                "splits": lab.SPLITS[name],
            },
        )
    if name in twin.TWIN_DATASETS:
        if source is not None:
            raise ConfigError(f"dataset {name} is generated by a twin; it takes no source files")
        spec = twin.TWIN_DATASETS[name]
        ok, why = _twin_available(spec.twin)
        if not ok:
            raise ConfigError(f"dataset {name} needs the {spec.twin} twin: {why}")
        est, tests, folder = twin.generate_records(spec, use_cache=use_cache, progress=progress)
        return Dataset(
            name=name,
            kind="twin",
            description=spec.description,
            est=est,
            tests=tests,
            init_samples=spec.init_samples,
            fs=est.fs,
            units=dict(est.units),
            references={},
            nonlinear=spec.nonlinear,
            meta={"twin": spec.twin, "noise": spec.noise, "seed": spec.seed, "cache": str(folder) if folder else None},
        )
    raise ConfigError(f"unknown dataset {name!r}; valid: {', '.join(dataset_names())}")
