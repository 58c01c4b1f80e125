"""Progress bars for long loops (tqdm), one switch for the whole process.

Library code wraps a long loop in :func:`progress`; the bar is drawn only when it is enabled *and* stderr is
a terminal, so pipes, log files and CI output stay clean. The command line switches bars off with
``--quiet`` (:func:`set_enabled`). The library never draws a bar on its own when stderr is not a TTY.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any

__all__ = ["progress", "set_enabled", "enabled"]

_ENABLED = True


def set_enabled(flag: bool) -> bool:
    """Switch progress bars on or off for this process; returns the previous setting."""
    global _ENABLED
    previous, _ENABLED = _ENABLED, bool(flag)
    return previous


def enabled() -> bool:
    """True when a bar would be drawn now: switched on and stderr is a terminal."""
    try:
        return _ENABLED and sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed stream
        return False


def progress(
    iterable: Iterable | None = None,
    *,
    total: int | None = None,
    desc: str | None = None,
    show: bool = True,
    **kwargs: Any,
):
    """A tqdm bar over ``iterable`` (or a manual one with ``total``), disabled unless :func:`enabled` and ``show``.

    The bar writes to stderr and disappears when done (``leave=False``) unless told otherwise.
    """
    from tqdm import tqdm

    kwargs.setdefault("leave", False)
    kwargs.setdefault("dynamic_ncols", True)
    return tqdm(iterable, total=total, desc=desc, disable=not (show and enabled()), file=sys.stderr, **kwargs)
