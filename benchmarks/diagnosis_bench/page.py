"""docs/diagnosis-benchmark.md, its figure and its summary, rendered from the stored rows of a run.

The page is a jinja2 template (``benchmarks/templates/diagnosis-benchmark.md.j2``: edit it, never the page); the
figure shows every case's outcome against its realised size, per family, and the reliability diagram of the
stated confidence; ``summary.json`` holds the scores :mod:`.check` compares a CI sample with.
"""

from __future__ import annotations

import json
import math
import platform
from pathlib import Path
from typing import Any

from sysid.data.safeio import atomic_write_text

from .score import CONFIDENT, _size, current, outcome

__all__ = ["DOCS_DIR", "PAGE", "render", "figure"]

_ROOT = Path(__file__).resolve().parents[2]
DOCS_DIR = _ROOT / "docs" / "diagnosis-benchmark"
PAGE = _ROOT / "docs" / "diagnosis-benchmark.md"
TEMPLATES = Path(__file__).resolve().parents[1] / "templates"


def _pct(r: dict[str, Any] | None) -> str:
    if not r or not r.get("n"):
        return "–"
    return f"{100 * r['rate']:.0f} % ({r['k']}/{r['n']}, ± {100 * r['se']:.0f})"


def _num(v: float | None, fmt: str = ".3g") -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def render(scores: dict[str, Any], meta: dict[str, Any], page: Path = PAGE, docs_dir: Path = DOCS_DIR) -> Path:
    """Write the page and ``summary.json`` (atomically) from ``scores`` (:func:`.score.score`) and ``meta``
    (how the run was made: command, date, machine, seeds)."""
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES), undefined=jinja2.StrictUndefined, keep_trailing_newline=True
    )
    env.filters["pct"] = _pct
    env.filters["num"] = _num
    cal = scores["calibration"]
    gaps = [abs(b["stated"] - b["observed"]) for b in cal["bins"] if b["n"] >= 20]
    text = env.get_template("diagnosis-benchmark.md.j2").render(
        s=scores,
        meta=meta,
        confident=CONFIDENT,
        max_gap=max(gaps) if gaps else None,
        figure=f"{docs_dir.name}/figure.png",
    )
    docs_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(docs_dir / "summary.json", json.dumps({"meta": meta, "scores": scores}, indent=1, default=float))
    atomic_write_text(page, text)
    return page


def figure(rows: list[dict[str, Any]], scores: dict[str, Any], path: Path) -> Path:
    """Outcome against realised size, one panel per family, and the reliability diagram."""
    from sysid.report.plots import pyplot, save_and_close

    plt = pyplot()
    fams = ["cantilever", "acoustic", "user"]
    fig, axes = plt.subplots(1, 4, figsize=(17, 5.5))
    colour = {"right": "tab:green", "wrong": "tab:red", "missed": "tab:grey"}
    for ax, fam in zip(axes, fams):
        sel = [r for r in rows if "error" not in r and r["case"]["family"] == fam and r["case"]["mechanism"]]
        mechs = sorted({r["case"]["mechanism"] for r in sel})
        for r in sel:
            o = outcome(current(r))["outcome"]
            ax.scatter(max(_size(r), 1e-5), mechs.index(r["case"]["mechanism"]), s=14, c=colour[o], alpha=0.7)
        for i, m in enumerate(mechs):
            dl = scores["detection_limits"].get(f"{fam}:{m}")
            if dl:
                ax.plot([dl, dl], [i - 0.35, i + 0.35], "k-", lw=1.5)
        ax.set_xscale("log")
        ax.set_yticks(range(len(mechs)), mechs, fontsize=8)
        ax.set_xlabel("realised size (RMS change / output RMS)")
        ax.set_title(f"{fam}: right / wrong / missed; | detection limit", fontsize=9)
    ax = axes[3]
    bins = scores["calibration"]["bins"]
    ax.plot([0, 1], [0, 1], "k--", lw=1)
    ax.plot([b["stated"] for b in bins], [b["observed"] for b in bins], "o-")
    for b in bins:
        ax.annotate(str(b["n"]), (b["stated"], b["observed"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("stated confidence")
    ax.set_ylabel("observed rate right")
    ax.set_title(f"reliability (Brier {_num(scores['calibration']['brier'])})", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_and_close(fig, path)
    return path


def machine() -> str:
    return f"{platform.machine()} {platform.processor() or ''}".strip()
