"""``piezotwin list {twins,protocols,effects,identifiers,datasets} [--json]``."""

from __future__ import annotations

import argparse

from benchmarks.cli.common import emit_json

KINDS = ("twins", "protocols", "effects", "identifiers", "datasets")


def register(sub) -> None:
    p = sub.add_parser("list", help="list twins, protocols, effects, identifiers or datasets")
    p.add_argument("kind", choices=KINDS)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def collect(kind: str) -> list[dict]:
    from twins.registry import available_twins, get_twin

    if kind == "twins":
        out = []
        for name in available_twins():
            cls = get_twin(name)
            out.append(
                {
                    "id": name,
                    "description": (cls.__doc__ or "").strip().splitlines()[0],
                    "default_effects": sorted(cls.default_effects()),
                }
            )
        return out
    if kind == "protocols":
        return [
            {"twin": n, "id": pid, "description": d}
            for n in available_twins()
            for pid, d in get_twin(n).PROTOCOLS.items()
        ]
    if kind == "effects":
        from twins.generic_effects import GENERIC_EFFECTS, generic_params_class

        generic = generic_params_class()  # the model-agnostic catalog that wraps a user's model or FMU
        return [e.to_dict(get_twin(n).Params) for n in available_twins() for e in get_twin(n).EFFECTS.values()] + [
            e.to_dict(generic) for e in GENERIC_EFFECTS.values()
        ]
    if kind == "identifiers":
        from sysid.registry import IDENTIFIERS, available_identifiers

        ok = set(available_identifiers())
        return [{"id": k, "class": v, "available": k in ok} for k, v in IDENTIFIERS.items()]
    if kind == "datasets":
        try:
            from benchmarks.datasets import list_datasets
        except ImportError:
            return []
        return list_datasets()
    raise ValueError(kind)


def run(args: argparse.Namespace) -> int:
    rows = collect(args.kind)
    if args.json:
        emit_json(rows)
        return 0
    if not rows:
        print(f"(no {args.kind} available)")
        return 0
    if args.kind == "effects":
        for r in rows:
            state = "on " if r["default_on"] else "off"
            params = ", ".join(f"{k} [{v.get('unit', '')}]" for k, v in r["params"].items())
            print(f"{r['twin']:<11} {r['id']:<28} default {state}  {r['description']}")
            print(f"{'':<11} {'':<28} params: {params or '-'}")
            print(f"{'':<11} {'':<28} signature: {r['signature']}")
        return 0
    for r in rows:
        print("  ".join(f"{v}" for v in r.values()))
    return 0
