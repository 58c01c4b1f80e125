"""The dissertation reproduced table by table (``piezotwin thesis``): Tables 4.2, 4.3, 5.2, 5.4–5.6 and Figures
3.4, 3.9, 5.13 measured on the twins, stored as rows and rendered into ``docs/dissertation.md``.

- :mod:`~benchmarks.thesis.targets` — the dissertation's numbers and their slips;
- :mod:`~benchmarks.thesis.plan` — the budgets (quick / middle / full tiers);
- :mod:`~benchmarks.thesis.cantilever`, :mod:`~benchmarks.thesis.acoustic` — the protocols, one task per fit;
- :mod:`~benchmarks.thesis.runner` — which fits each row needs, run here or on Dask workers;
- :mod:`~benchmarks.thesis.rows`, :mod:`~benchmarks.thesis.explain` — the stored-row format, the protocol
  differences and the measured explanations; :mod:`~benchmarks.thesis.page` — the page and the histogram.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["ROWS_PATH", "PAGE_PATH", "GRID_PATH", "HISTOGRAM_NAME", "write_page"]

_ROOT = Path(__file__).resolve().parents[2]
#: stored rows, the generated page and the Figure 5.13 histogram beside it (a source checkout's paths)
ROWS_PATH = _ROOT / "docs" / "dissertation" / "rows.json"
PAGE_PATH = _ROOT / "docs" / "dissertation.md"
#: Table 5.3's stored random sample (:mod:`benchmarks.thesis.grid`), read by the page when present
GRID_PATH = _ROOT / "docs" / "dissertation" / "grid-5.3.json"
HISTOGRAM_NAME = "fig-5.13.png"


def write_page(
    rows: dict[str, dict[str, Any]],
    page: str | Path,
    histogram_dir: str | Path | None = None,
    draw: bool = True,
    grid: str | Path | None = None,
) -> str:
    """Render the page from ``rows`` and write it (atomically); the histogram goes to ``histogram_dir`` (default:
    the ``dissertation/`` folder beside the page) when ``draw`` and the Figure 5.13 rows are stored; Table 5.3's
    sample is read from ``grid`` (default: ``grid-5.3.json`` in that folder) when present."""
    import os

    from benchmarks.thesis.grid import load as load_grid
    from benchmarks.thesis.page import render, write_histogram
    from sysid.data.safeio import atomic_write_text

    page = Path(page)
    hdir = Path(histogram_dir) if histogram_dir else page.parent / page.stem
    link = os.path.relpath(hdir / HISTOGRAM_NAME, page.parent)
    has_fig = "fig-5.13/est" in rows and "fig-5.13/val" in rows
    if draw and has_fig:
        hdir.mkdir(parents=True, exist_ok=True)
        write_histogram(rows, hdir / HISTOGRAM_NAME)
    text = render(rows, link if has_fig else None, load_grid(grid or hdir / GRID_PATH.name))
    atomic_write_text(page, text)
    return text
