"""What every stage of the main job (:mod:`benchmarks.mainjob`) shares: the :class:`Context` it writes into and
:class:`StageSkipped`, raised by a stage whose parts are not available."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sysid.report.plots import save_and_close


class StageSkipped(Exception):
    """Raised by a stage whose prerequisites are not available; the message says why."""


@dataclass
class Context:
    report_dir: Path
    quick: bool
    figures: list[tuple[str, str]] = field(default_factory=list)  # (title, relative png path), in stage order
    sections: list[tuple[str, str]] = field(default_factory=list)  # (title, html)
    data: dict[str, Any] = field(default_factory=dict)
    verbose: bool = True
    # what this run did not recompute: (what, why, the command that does it), shown in the report's header
    left: list[tuple[str, str, str]] = field(default_factory=list)

    def save_figure(self, fig, name: str, title: str) -> str:
        """Save a matplotlib figure as ``fig/<name>.png`` under the report folder; returns the relative path."""
        rel = f"fig/{name}.png"
        save_and_close(fig, self.report_dir / rel, dpi=80)
        self.figures.append((title, rel))
        return rel

    def section(self, title: str, content_html: str) -> None:
        self.sections.append((title, content_html))

    def leave(self, what: str, why: str, command: str) -> None:
        """Name something this run left out, why, and the command that computes it."""
        self.left.append((what, why, command))
