"""Published reference numbers: free-run RMSE on the official test data, in the units of the dataset's y.

The numbers and their sources live in ``benchmarks/settings/published.toml`` (:mod:`benchmarks.published`); here
they are per dataset, test and kind: ``linear_baseline`` (best linear approximation, BLA), ``best_published`` (the
best published result of any kind of model), ``best_published_black_box``, ``best_published_grey_box`` and
``sysidentpy`` (SysIdentPy's published polynomial NARX number), each with the model that reached it.
"""

from __future__ import annotations

from typing import Any

from benchmarks.published import references as _published_references

# dataset -> test name -> kind -> {value, unit, model}
REFERENCES: dict[str, dict[str, dict[str, dict[str, Any]]]] = _published_references()


def references_for(dataset: str) -> dict[str, dict[str, dict[str, Any]]]:
    """Reference numbers of ``dataset`` by test name (empty when none are published)."""
    return {
        t: {k: dict(v, metric="free-run RMSE") for k, v in kinds.items()}
        for t, kinds in REFERENCES.get(dataset, {}).items()
    }
