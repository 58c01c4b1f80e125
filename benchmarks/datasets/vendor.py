"""Make the compact vendored copies of the lab data: ``python -m benchmarks.datasets.vendor SHARED_DATA_DIR``.

For each lab dataset this reads the original published files with the same readers that
``load_dataset(name, source=...)`` uses (:mod:`benchmarks.datasets.lab`), and writes into
``benchmarks/data/<folder>/``:

- one Record ``.npz`` per raw record (arrays ``u``, ``y`` as float64 exactly as parsed from the original — no
  cast, no resampling, nothing dropped —, scalar ``fs``, ``meta`` JSON with units and provenance), compressed
  with ``numpy.savez_compressed``; readable with ``sysid.data.io.read_record`` or plain ``numpy.load``;
- ``SOURCE.txt`` and every licence/readme file of the source folder, copied unchanged;
- ``PROVENANCE.txt``: how the npz files were made, with the sha256 of every original file and of every array.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
from pathlib import Path

import numpy as np

from benchmarks.datasets import lab

COPY_PATTERNS = ("SOURCE.txt", "LICENSE*", "README*")


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def sha256_array(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()


def vendor(name: str, shared_data: Path, out_dir: Path = lab.DATA_DIR) -> list[Path]:
    spec = lab.LAB_SPECS[name]
    src = Path(shared_data) / spec.folder
    dst = out_dir / spec.folder
    dst.mkdir(parents=True, exist_ok=True)
    raws = lab.read_original(name, src)
    written = []
    originals = {f: sha256_file(src / f) for f in spec.originals}
    lines = [
        f"PROVENANCE of benchmarks/data/{spec.folder}/ (dataset '{name}')",
        "",
        "Made by `python -m benchmarks.datasets.vendor SHARED_DATA_DIR` from the original files below",
        "(read by benchmarks.datasets.lab.read_original, the same reader that load_dataset(name, source=...) uses).",
        "Values are float64 exactly as parsed from the originals (no cast, no resampling, nothing dropped);",
        "stored with numpy.savez_compressed as Record files (u, y, fs, meta).",
        "",
        "Original files (sha256):",
    ]
    lines += [f"  {h}  {f}" for f, h in originals.items()]
    lines += ["", "Vendored files (samples, fs, sha256 of the float64 bytes of u and y):"]
    for stem, rec in raws.items():
        meta = {
            "units": dict(rec.units),
            "dataset": name,
            "record": stem,
            "provenance": {
                "original_files": {f: originals[f] for f in rec.meta["provenance"]["files"] if f in originals},
                "made_by": "benchmarks.datasets.vendor",
                "see": "PROVENANCE.txt, SOURCE.txt",
            },
        }
        path = dst / f"{stem}.npz"
        np.savez_compressed(
            path,
            u=np.asarray(rec.u, dtype=np.float64),
            y=np.asarray(rec.y, dtype=np.float64),
            fs=np.float64(rec.fs),
            meta=np.array(json.dumps(meta)),
        )
        written.append(path)
        lines.append(
            f"  {path.name}: n={len(rec)}, fs={rec.fs:g} Hz, u {sha256_array(rec.u)}, y {sha256_array(rec.output)}"
        )
    for pattern in COPY_PATTERNS:
        for f in sorted(src.glob(pattern)):
            shutil.copyfile(f, dst / f.name)
            written.append(dst / f.name)
    (dst / "PROVENANCE.txt").write_text("\n".join(lines) + "\n")
    written.append(dst / "PROVENANCE.txt")
    return written


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("shared_data", type=Path, help="folder holding the original data folders (../shared/data)")
    p.add_argument("--datasets", default=",".join(lab.LAB_SPECS), help="comma-separated lab datasets")
    args = p.parse_args(argv)
    for name in [s.strip() for s in args.datasets.split(",") if s.strip()]:
        files = vendor(name, args.shared_data)
        size = sum(f.stat().st_size for f in files)
        print(f"{name}: {len(files)} files, {size / 1e6:.2f} MB -> {files[0].parent}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
