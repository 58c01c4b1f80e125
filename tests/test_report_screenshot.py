"""The report shows the truth, checked in headless Chromium: the page is rendered to a PNG and its
pixels show the whole measured/predicted record (a feature at the very end of the record is drawn), the
correlation tests' confidence bands (visible, not a hairline on a ±1 axis) and the provenance block.

Each check is also run on a control figure drawn the old way (first 1000 samples only; a fixed ±1 axis) on
the same page, and must fail there: the checks can fail.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = Path(shutil.which("chromium") or "/usr/bin/chromium")  # Debian package "chromium" (.ci/run installs it)
pytestmark = pytest.mark.browser

_PROBE = (
    "<script>window.addEventListener('load',function(){var out={h:document.documentElement.scrollHeight,"
    "w:document.documentElement.scrollWidth,img:{}};var im=document.images;for(var i=0;i<im.length;i++){"
    "var r=im[i].getBoundingClientRect();out.img[im[i].getAttribute('src')]=[r.left,r.top,r.width,r.height,"
    "im[i].naturalWidth];}var p=document.getElementById('provenance');if(p){var r=p.getBoundingClientRect();"
    "out.prov=[r.left,r.top,r.width,r.height];out.provText=p.innerText;}var d=document.createElement('pre');"
    "d.id='probe';d.textContent='PROBE '+JSON.stringify(out);document.body.appendChild(d);});</script>"
)


def _chromium(args: list[str], tmp: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            str(CHROMIUM),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--disable-background-networking",
            "--no-first-run",
            "--force-device-scale-factor=1",
            f"--user-data-dir={tmp / 'chromium-profile'}",
            "--virtual-time-budget=10000",
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )


def render(index: Path, tmp: Path) -> tuple[dict, np.ndarray]:
    """(layout of the page's images and provenance block, screenshot as an RGB float array)."""
    probe = index.with_name("_probe.html")
    probe.write_text(index.read_text().replace("</body>", _PROBE + "</body>"))
    proc = _chromium(["--window-size=1280,1000", "--dump-dom", probe.resolve().as_uri()], tmp)
    m = re.search(r"PROBE (\{.*\})", proc.stdout)
    assert m, f"chromium gave no layout (rc {proc.returncode}): {proc.stderr[-800:]}"
    layout = json.loads(m.group(1).replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">"))
    shot = tmp / "page.png"
    proc = _chromium(
        [f"--window-size=1280,{int(layout['h']) + 10}", f"--screenshot={shot}", probe.resolve().as_uri()], tmp
    )
    probe.unlink()
    assert shot.exists(), f"chromium wrote no screenshot (rc {proc.returncode}): {proc.stderr[-800:]}"
    import matplotlib.image as mpimg

    return layout, mpimg.imread(shot)[..., :3].astype(float)


def _crop(img: np.ndarray, rect) -> np.ndarray:
    x, y, w, h = (int(round(v)) for v in rect[:4])
    return img[y : y + h, x : x + w]


def _mask(img: np.ndarray, hex_color: str, tol: float = 0.06) -> np.ndarray:
    rgb = np.array([int(hex_color[i : i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return np.all(np.abs(img - rgb) < tol, axis=-1)


def band_fraction(img: np.ndarray) -> float:
    """Share of the figure's pixels painted in the band colour."""
    from sysid.report.plots import BAND_COLOR

    return float(_mask(img, BAND_COLOR).mean())


def trace_reaches_end(img: np.ndarray) -> tuple[float, float]:
    """(share of the figure's width that the first prediction's colour spans in the whole-record panel,
    ratio of that trace's vertical extent in its last 3 % of columns to its extent before): the test record
    has a burst of 3× amplitude in its last 5 %, which a plot of its start cannot show."""
    from sysid.report.plots import PREDICTED_COLORS

    top = img[: int(img.shape[0] * 0.5)]  # the whole-record panel is the upper one
    m = _mask(top, PREDICTED_COLORS[0], tol=0.12)
    cols = np.flatnonzero(m.any(axis=0))
    if cols.size < 10:
        return 0.0, 0.0
    span = (cols[-1] - cols[0]) / img.shape[1]
    n = cols.size

    def extent(c):  # vertical extent of the trace over a range of columns
        rows = np.flatnonzero(m[:, c].any(axis=1))
        return float(np.ptp(rows)) if rows.size else 0.0

    end = extent(cols[int(0.97 * n) :])
    before = extent(cols[int(0.1 * n) : int(0.8 * n)])
    return float(span), float(end / max(before, 1.0))


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    if not CHROMIUM.exists():
        pytest.skip("headless browser test needs /usr/bin/chromium (Debian package 'chromium'); not installed")
    from sysid.report.plots import pyplot

    plt = pyplot()

    from benchmarks.mainjob import Context, _write_report
    from sysid.evaluation.residuals import correlation_tests
    from sysid.report.plots import draw_correlation_test, plot_measured_vs_predicted

    tmp = tmp_path_factory.mktemp("shot")
    rep = tmp / "report"
    ctx = Context(report_dir=rep, quick=True)
    fs, n = 100.0, 20000
    t = np.arange(n) / fs
    y = np.sin(2 * np.pi * 0.2 * t)
    y[-n // 20 :] *= 3.0  # the burst at the end of the record
    yhat = 0.97 * y + 0.02
    (rep / "fig").mkdir(parents=True)
    plot_measured_vs_predicted(t, y, {"model": yhat}, rep / "fig" / "trace.png", unit="µm")
    ctx.figures.append(("whole record", "fig/trace.png"))
    rng = np.random.default_rng(0)
    res = correlation_tests(rng.standard_normal(n), rng.standard_normal(n), max_lag=20)  # white: band ±0.014
    fig, axes = plt.subplots(1, 5, figsize=(13, 2.8))
    for ax, test in zip(axes, res["tests"]):
        draw_correlation_test(ax, test)
    fig.tight_layout()
    ctx.save_figure(fig, "tests", "correlation tests")
    # controls, drawn the way a report that hides the truth would draw them (the start only, a fixed ±1 axis)
    plot_measured_vs_predicted(t[:1000], y[:1000], {"model": yhat[:1000]}, rep / "fig" / "control_trace.png", unit="µm")
    ctx.figures.append(("control: first 1000 samples", "fig/control_trace.png"))
    fig, axes = plt.subplots(1, 5, figsize=(13, 2.8))
    for ax, test in zip(axes, res["tests"]):
        draw_correlation_test(ax, test)
        ax.set_ylim(-1, 1)
    fig.tight_layout()
    ctx.save_figure(fig, "control_tests", "control: fixed ±1 axis")
    index = _write_report(ctx, [{"stage": "screenshot test", "status": "done", "message": "ok", "seconds": 0.0}])
    layout, img = render(index, tmp)
    return layout, img


def test_full_length_trace_is_drawn(page):
    layout, img = page
    span, end_ratio = trace_reaches_end(_crop(img, layout["img"]["fig/trace.png"]))
    assert span > 0.75 and end_ratio > 2.0, (span, end_ratio)
    span_c, end_c = trace_reaches_end(_crop(img, layout["img"]["fig/control_trace.png"]))
    assert span_c > 0.75 and end_c < 1.5, (span_c, end_c)  # spans the axes but never reaches the burst


def test_confidence_bands_are_visible(page):
    layout, img = page
    shown = band_fraction(_crop(img, layout["img"]["fig/tests.png"]))
    control = band_fraction(_crop(img, layout["img"]["fig/control_tests.png"]))
    assert shown > 0.05 and control < 0.01, (shown, control)


def test_provenance_is_present(page):
    from importlib.metadata import version

    layout, img = page
    assert "prov" in layout and layout["prov"][3] > 50
    text = layout["provText"]
    for key in (
        "Provenance",
        f"piezotwin {version('piezotwin')}",
        "git commit",
        "command",
        "date (UTC)",
        "machine",
        "data",
    ):
        assert key in text, key
    assert re.search(r"[0-9a-f]{40}|not a git checkout", text)
    block = _crop(img, layout["prov"])
    assert (block.mean(axis=-1) < 0.35).mean() > 0.01  # the text is drawn (dark pixels), not an empty box
