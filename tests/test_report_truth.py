"""The report's building blocks tell the truth: loops over whole periods, correlation-test axes
scaled to the data with the band visible, whole-record traces that keep every extreme, and a provenance
record with real hashes."""

from __future__ import annotations

import hashlib
import re

import numpy as np

from sysid.report.plots import _envelope, draw_correlation_test, whole_periods
from sysid.report.provenance import collect, html_block


def test_loops_cover_whole_periods():
    fs = 10e3
    # the thesis' 0.1 Hz sine is one 10 s period: the whole segment, not its second half
    assert whole_periods(100_000, fs, 0.1) == slice(0, 100_000)
    s = whole_periods(20_000, fs, 100.0)  # 100 Hz: the last 100 samples = one period
    assert s.stop - s.start == 100 and s.stop == 20_000
    s = whole_periods(20_000, fs, 100.0, periods=3)
    assert s.stop - s.start == 300
    assert whole_periods(50, fs, 1.0) == slice(0, 50)  # shorter than a period: everything there is


def test_correlation_axes_scale_to_the_data_and_show_the_band():
    from sysid.report.plots import pyplot

    plt = pyplot()

    band = 1.96 / np.sqrt(20_000)
    small = {
        "name": "r_ee",
        "passed": True,
        "lags": list(range(1, 21)),
        "values": list(0.5 * band * np.sin(np.arange(20))),
        "band": band,
    }
    big = {**small, "passed": False, "values": [0.6] + [0.0] * 19}
    fig, ax = plt.subplots(1, 2)
    draw_correlation_test(ax[0], small)
    draw_correlation_test(ax[1], big)
    lo, hi = ax[0].get_ylim()
    assert hi == -lo and 1.5 * band <= hi < 0.05  # not ±1: the band fills a visible part of the axis
    assert ax[1].get_ylim()[1] >= 0.6  # a large value is never clipped
    assert "band ±0.014" in ax[0].get_title()
    plt.close(fig)


def test_whole_record_envelope_keeps_every_extreme():
    rng = np.random.default_rng(1)
    y = rng.standard_normal(1_000_000)
    y[999_990] = 25.0  # one spike at the very end
    t = np.arange(y.size) / 1e3
    te, ye = _envelope(t, y, 20_000)
    assert ye.size <= 20_000 and te[0] <= t[100] and te[-1] >= t[-101]  # first and last bins present
    assert ye.max() == 25.0 and ye.min() == y.min()
    assert np.all(np.diff(te) >= 0)  # time order kept


def test_provenance_hashes_files_and_names_the_source(tmp_path):
    f = tmp_path / "data.csv"
    f.write_bytes(b"t,u,y\n0,1,2\n")
    prov = collect(files=[f], command=["piezotwin", "diagnose", "cantilever", "--data", str(f)])
    assert prov["data"] == [{"file": str(f), "bytes": 12, "sha256": hashlib.sha256(b"t,u,y\n0,1,2\n").hexdigest()}]
    assert prov["command"].startswith("piezotwin diagnose cantilever --data ")
    assert re.match(r"[0-9a-f]{40}|unknown", prov["commit"])
    assert re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", prov["date_utc"])
    block = html_block(prov)
    assert block.startswith("<section id='provenance'>") and prov["data"][0]["sha256"] in block


def test_one_page_template_escapes_data_and_ends_with_the_provenance(tmp_path):
    from sysid.report.html import figure, table, write_page

    prov = collect(files=[])
    path = write_page(
        tmp_path / "index.html",
        "a <b> & c",
        [table(["k", "v"], [["x", "<i>ok</i>"]], row_classes=["done"]), figure("fig/a b.png", "A & B")],
        css="h1{}",
        provenance=prov,
    )
    page = path.read_text()
    assert page.startswith("<!doctype html>") and page.endswith("</body></html>")
    assert "<title>a &lt;b&gt; &amp; c</title>" in page and "<style>h1{}table{" in page
    assert "<tr class='done'><td>x</td><td><i>ok</i></td></tr>" in page  # cells are HTML: the caller escapes data
    assert "<figure><img src='fig/a b.png' alt='A &amp; B'><figcaption>A &amp; B</figcaption></figure>" in page
    assert page.index("<section id='provenance'>") > page.index("<figure>")
    assert html_block(prov) in page
