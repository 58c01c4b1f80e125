"""Collections of generated records: a twin's protocol over a parameter grid × seeds, stored as HDF5.

``piezotwin generate TWIN PROTOCOL --grid distance_m=0.02-0.04-0.08,temperature_c=20-40 --seeds 0-9 -o OUT.h5``
runs the protocol once per grid point and seed (one task each, :mod:`benchmarks.execution`) and writes

* ``OUT.h5`` — one HDF5 file per collection, readable with h5py (or any HDF5 tool) without this package::

      /                      attrs: format = "piezotwin-collection/1", twin, protocol, grid (JSON), seeds (JSON)
      /records/r00000        one group per record, in grid order (parameters vary slowest-first, seed fastest)
          u, y               float64 datasets, the samples exactly as generated (gzip + shuffle: lossless)
          attrs: fs [Hz], units_u, units_y, twin, protocol, seed, init_samples, parameters (JSON: the
                 twin's full parameter set), grid_point (JSON: the swept values), effects (JSON list),
                 protocol_options (JSON), meta (JSON: the record's whole metadata)

* ``OUT_index.csv`` — the index table: one row per record (group path, swept values, seed, samples, fs).

``init_samples`` is the record's initialisation window in samples (``meta['init_samples']``; 0 for twin
records, which start at rest). Both files are written to a temporary name and moved into place
(``os.replace``), so a reader never sees half a collection.
"""

from __future__ import annotations

import csv
import itertools
import json
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from sysid.config import coerce
from sysid.data.record import Record
from sysid.errors import ConfigError

FORMAT = "piezotwin-collection/1"
_VALUE_SEP = re.compile(r"(?<![eE])-")  # values are separated by '-', except the exponent sign of 1e-3


def parse_grid_spec(spec: str, params_cls: type) -> dict[str, list[Any]]:
    """``"distance_m=0.02-0.04-0.08,temperature_c=20-40"`` → {name: [values]} coerced to each parameter's type.

    Items are separated by ``,`` and the values of one item by ``-`` (so values cannot be negative)."""
    from twins.base import param_info

    info = param_info(params_cls)
    grid: dict[str, list[Any]] = {}
    for item in str(spec or "").split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise ConfigError(f"--grid: expected PARAM=V1-V2-..., got {item!r}")
        name, _, text = item.partition("=")
        name = name.strip()
        if name not in info:
            raise ConfigError(f"--grid: unknown parameter {name!r}; valid: {', '.join(info)}")
        if name in grid:
            raise ConfigError(f"--grid: {name!r} given twice")
        values = [v.strip() for v in _VALUE_SEP.split(text) if v.strip()]
        if not values:
            raise ConfigError(f"--grid: no values for {name!r}")
        grid[name] = [coerce(v, info[name].default, name) for v in values]
    if not grid:
        raise ConfigError("--grid: empty; e.g. distance_m=0.02-0.04-0.08,temperature_c=20-40")
    return grid


def parse_seeds(text: str) -> list[int]:
    """``"0-9"`` → [0 … 9]; ``"0,3,7"`` and mixtures (``"0-2,5"``) too."""
    seeds: list[int] = []
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        try:
            if "-" in part:
                a, _, b = part.partition("-")
                lo, hi = int(a), int(b)
                if hi < lo or hi - lo > 100_000:
                    raise ValueError
                seeds += list(range(lo, hi + 1))
            else:
                seeds.append(int(part))
        except ValueError:
            raise ConfigError(f"--seeds: expected A-B or A,B,... of non-negative integers, got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise ConfigError(f"--seeds: expected A-B or A,B,... of non-negative integers, got {text!r}")
    return list(dict.fromkeys(seeds))


def grid_points(grid: dict[str, list[Any]], seeds: list[int]) -> list[tuple[dict[str, Any], int]]:
    """Every (parameter values, seed), parameters varying slowest-first, seed fastest."""
    keys = list(grid)
    return [(dict(zip(keys, values)), seed) for values in itertools.product(*(grid[k] for k in keys)) for seed in seeds]


def generate_point(twin, changes: dict[str, Any], seed: int, protocol: str, options: dict[str, Any]) -> Record:
    """One record: ``twin`` with ``changes`` and measurement-noise ``seed`` runs ``protocol`` (a pure function
    of its arguments: a Dask worker returns the same samples as this process)."""
    tw = type(twin)(twin.with_params(**changes).params, twin.effects, seed)
    return tw.generate(protocol, **options)


def _json(obj: Any, sort: bool = True) -> str:
    from sysid.data.jsonio import clean_json

    return json.dumps(clean_json(obj), sort_keys=sort, default=str)


class CollectionWriter:
    """Writes records into ``path`` (temporary name until :meth:`close`) and the index table beside it."""

    def __init__(self, path: str | Path, twin: str, protocol: str, grid: dict[str, list[Any]], seeds: list[int]):
        import h5py

        self.path = Path(path)
        self.index_path = self.path.with_name(self.path.stem + "_index.csv")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}")
        self.grid = grid
        self.rows: dict[int, dict[str, Any]] = {}
        self.h5 = h5py.File(self._tmp, "w")
        self.h5.attrs.update(
            {
                "format": FORMAT,
                "twin": twin,
                "protocol": protocol,
                "grid": _json(grid, sort=False),
                "seeds": _json(seeds),
            }
        )
        self.h5.create_group("records")

    def add(self, index: int, point: dict[str, Any], seed: int, rec: Record) -> None:
        name = f"r{index:05d}"
        g = self.h5["records"].create_group(name)
        for key in ("u", "y"):
            data = getattr(rec, key)
            if data is None:
                continue
            g.create_dataset(key, data=np.asarray(data), compression="gzip", compression_opts=4, shuffle=True)
        meta = rec.meta
        g.attrs.update(
            {
                "fs": float(rec.fs),
                "units_u": rec.units.get("u", ""),
                "units_y": rec.units.get("y", ""),
                "twin": str(meta.get("twin", "")),
                "protocol": str(meta.get("protocol", "")),
                "seed": int(seed),
                "init_samples": int(meta.get("init_samples", 0)),
                "parameters": _json(meta.get("params", {})),
                "grid_point": _json(point, sort=False),
                "effects": _json(meta.get("effects", [])),
                "protocol_options": _json(meta.get("protocol_options", {})),
                "meta": _json(meta),
            }
        )
        self.rows[index] = {
            "record": f"records/{name}",
            **{k: point[k] for k in self.grid},
            "seed": seed,
            "n_samples": len(rec),
            "fs_hz": float(rec.fs),
        }

    def close(self) -> tuple[Path, Path]:
        """Finish both files and move them into place; returns (HDF5 path, index path)."""
        self.h5.close()
        tmp_index = self.index_path.with_name(f".{self.index_path.name}.tmp-{os.getpid()}")
        with open(tmp_index, "w", newline="") as fh:
            rows = [self.rows[i] for i in sorted(self.rows)]
            w = csv.DictWriter(fh, fieldnames=["record", *self.grid, "seed", "n_samples", "fs_hz"])
            w.writeheader()
            w.writerows(rows)
        os.replace(self._tmp, self.path)
        os.replace(tmp_index, self.index_path)
        return self.path, self.index_path

    def abort(self) -> None:
        try:
            self.h5.close()
        finally:
            self._tmp.unlink(missing_ok=True)


def generate_collection(
    twin,
    protocol: str,
    grid: dict[str, list[Any]],
    seeds: list[int],
    out: str | Path,
    options: dict[str, Any] | None = None,
    executor=None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the grid × seeds (one task each) and write the collection; returns a summary."""
    from benchmarks.execution import Executor

    if Path(out).suffix.lower() not in (".h5", ".hdf5"):
        raise ConfigError(f"generate --grid writes an HDF5 collection: -o must end in .h5 or .hdf5, got {out}")
    twin.check_protocol(protocol)
    ex = executor or Executor()
    points = grid_points(grid, seeds)
    writer = CollectionWriter(out, twin.name, protocol, grid, seeds)
    tw = ex.share(twin)
    try:
        ex.map(
            generate_point,
            [(tw, p, s, protocol, dict(options or {})) for p, s in points],
            desc="generate",
            progress=progress,
            on_result=lambda i, rec: writer.add(i, points[i][0], points[i][1], rec),
            keep=False,
        )
    except BaseException:
        writer.abort()
        raise
    h5_path, index_path = writer.close()
    return {
        "file": str(h5_path),
        "index": str(index_path),
        "records": len(points),
        "twin": twin.name,
        "protocol": protocol,
        "grid": grid,
        "seeds": seeds,
    }


def read_collection(path: str | Path) -> list[Record]:
    """The records of a collection (h5py only), in index order — the inverse of :class:`CollectionWriter`."""
    import h5py

    out = []
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT:
            raise ConfigError(f"{path}: not a piezotwin collection (format {f.attrs.get('format')!r})")
        for name in sorted(f["records"]):
            g = f["records"][name]
            out.append(
                Record(
                    u=g["u"][()],
                    y=g["y"][()] if "y" in g else None,
                    fs=float(g.attrs["fs"]),
                    units={"u": str(g.attrs["units_u"]), "y": str(g.attrs["units_y"])},
                    meta=json.loads(g.attrs["meta"]),
                )
            )
    return out
