"""Summarise a pytest-benchmark JSON into the Markdown table of the README: ``python -m tests.perf.summarise
[docs/perf/bench.json] [-o docs/perf/summary.md]``.

For every benchmark: mean and min time per call, throughput when ``extra_info['items']`` is given, its
reference (``extra_info['reference']`` or the naming rule of :mod:`tests.perf.conftest`) with the speed
ratio reference/ours (> 1 = faster than the reference; per item when both give ``items``; ``reference: None``
says that no benchmark of the run is one), and its target
(``extra_info['target_s']``) with the margin, and ``extra_info['note']`` (what the mean does not say: N, rate, load,
CPU time, the goal's own measure). The machine line comes from the JSON (CPU, cores) — timings on a shared
machine are inflated."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

DEFAULT_JSON = Path(__file__).resolve().parents[1] / "results" / "bench.json"
REF_WORDS = ("reference", "sysidentpy", "scipy")


def _short(name: str) -> str:
    return name.split("[")[0].removeprefix("test_")


def _label(name: str) -> str:
    """Display name: without ``test_``, with the parameter id (``frols_vs_sysidentpy[1000]``)."""
    return name.removeprefix("test_")


def _is_reference(name: str) -> bool:
    n = name.lower()
    if "reference" in n:
        return True
    return any(w in n for w in REF_WORDS) and "_vs_" not in n  # "ours_vs_theirs" measures both sides itself


def _words(name: str) -> list[str]:
    return _short(name).lower().split("_")


def pair_references(benches: list[dict[str, Any]]) -> dict[str, str]:
    """fullname -> fullname of its reference."""
    out: dict[str, str] = {}
    for b in benches:
        ref = (b.get("extra_info") or {}).get("reference")
        if ref:
            match = next(
                (x for x in benches if x["name"] == ref or _short(x["name"]) == _short(ref) or x["fullname"] == ref),
                None,
            )
            if match is not None:
                out[b["fullname"]] = match["fullname"]
    refs = [b for b in benches if _is_reference(b["name"])]
    for b in benches:
        info = b.get("extra_info") or {}
        if b["fullname"] in out or _is_reference(b["name"]) or info.get("ratio") is not None:
            continue
        if "reference" in info and not info["reference"]:  # stated: nothing of this run is its reference
            continue
        module = b["fullname"].split("::")[0]
        best, best_len = None, 0
        for r in refs:
            if r["fullname"].split("::")[0] != module:
                continue
            wb, wr = _words(b["name"]), _words(r["name"])
            k = 0
            while k < min(len(wb), len(wr)) and wb[k] == wr[k]:
                k += 1
            if k > best_len:
                best, best_len = r, k
        if best is not None:
            out[b["fullname"]] = best["fullname"]
    return out


def _fmt_s(s: float) -> str:
    if s >= 1:
        return f"{s:.2f} s"
    if s >= 1e-3:
        return f"{s * 1e3:.1f} ms"
    return f"{s * 1e6:.0f} µs"


def summarise(data: dict[str, Any]) -> str:
    benches = data.get("benchmarks", [])
    mi = data.get("machine_info", {})
    cpu = (mi.get("cpu") or {}).get("brand_raw", mi.get("processor", "?"))
    cores = (mi.get("cpu") or {}).get("count", "?")
    refs = pair_references(benches)
    by_full = {b["fullname"]: b for b in benches}
    lines = [
        f"Machine: {cpu}, {cores} logical cores, Python {mi.get('python_version', '?')}; "
        f"{data.get('datetime', '')[:19]}. Shared machine: absolute times are inflated.",
        "",
        "| benchmark | mean | min | throughput | reference (mean) | speed-up vs reference | target | meets target "
        "| notes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for b in sorted(benches, key=lambda x: x["fullname"]):
        st, info = b["stats"], b.get("extra_info") or {}
        mean, mn = st["mean"], st["min"]
        items = info.get("items")
        thr = f"{items / mean / 1e6:.3g} M/s" if items else ""
        ref = by_full.get(refs.get(b["fullname"], ""))
        if ref is not None:
            rtxt = f"{_label(ref['name'])} ({_fmt_s(ref['stats']['mean'])})"
            r_items = (ref.get("extra_info") or {}).get("items")
            if items and r_items:  # different sizes: compare time per item
                ratio = f"{(ref['stats']['mean'] / r_items) / (mean / items):.3g}× per item"
            else:
                ratio = f"{ref['stats']['mean'] / mean:.3g}×"
        elif info.get("ratio") is not None:  # a ratio measured inside the benchmark (e.g. vs SysIdentPy)
            rtxt, ratio = "measured in the benchmark", f"{float(info['ratio']):.3g}×"
        else:
            rtxt, ratio = "", ""
        tgt = info.get("target_s")
        ttxt = f"< {_fmt_s(float(tgt))}" if tgt else ""
        ok = ("yes" if mean <= float(tgt) else f"no ({mean / float(tgt):.2g}× over)") if tgt else ""
        module = b["fullname"].split("::")[0].rsplit("/", 1)[-1].removesuffix(".py").removeprefix("test_")
        lines.append(
            f"| {module}: {_label(b['name'])} | {_fmt_s(mean)} | {_fmt_s(mn)} | {thr} | {rtxt} | {ratio} | "
            f"{ttxt} | {ok} | {str(info.get('note', '')).replace('|', '/')} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Summarise pytest-benchmark JSON as a Markdown table of ratios.")
    p.add_argument("json", nargs="?", type=Path, default=DEFAULT_JSON)
    p.add_argument("-o", "--output", type=Path, help="write the table here (default: print)")
    args = p.parse_args(argv)
    if not args.json.exists():
        print(f"{args.json}: not found (run `make bench` first)", file=sys.stderr)
        return 2
    try:
        data = json.loads(args.json.read_text())
    except json.JSONDecodeError as exc:
        print(f"{args.json}: not a pytest-benchmark JSON ({exc.msg})", file=sys.stderr)
        return 2
    text = summarise(data)
    if args.output:
        args.output.write_text(text)
        print(f"summary -> {args.output}")
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
