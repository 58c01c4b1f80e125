"""The main job's report opens in a browser without a server: headless Chromium loads report/index.html from
the file system and every image loads (naturalWidth > 0)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")

pytestmark = pytest.mark.browser

_CHECK = (
    "<script>window.addEventListener('load',function(){var im=document.images,b=[];"
    "for(var i=0;i<im.length;i++){if(!(im[i].complete&&im[i].naturalWidth>0))b.push(im[i].getAttribute('src'));}"
    "var d=document.createElement('pre');d.id='imgcheck';d.textContent='IMGCHECK '+im.length+' '+JSON.stringify(b);"
    "document.body.appendChild(d);});</script>"
)


def broken_images(index: Path, tmp: Path) -> tuple[int, list[str]]:
    """(number of images, src of those that did not load) as headless Chromium renders ``index``."""
    probe = index.with_name("_imgcheck.html")
    probe.write_text(index.read_text().replace("</body>", _CHECK + "</body>"))
    try:
        proc = subprocess.run(
            [
                str(CHROMIUM),
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--no-first-run",
                f"--user-data-dir={tmp / 'chromium-profile'}",
                "--virtual-time-budget=10000",
                "--dump-dom",
                probe.resolve().as_uri(),
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        probe.unlink()
    m = re.search(r"IMGCHECK (\d+) (\[.*?\])", proc.stdout)
    assert m, f"chromium gave no result (rc {proc.returncode}): {proc.stderr[-500:]}"
    return int(m.group(1)), json.loads(m.group(2))


@pytest.fixture
def chromium():
    if not CHROMIUM.exists():
        pytest.skip("headless browser test needs /usr/bin/chromium (Debian package 'chromium'); not installed")
    return CHROMIUM


def _check_report(rep: Path, summary: dict, tmp_path: Path) -> None:
    n, broken = broken_images(rep / "index.html", tmp_path)
    assert broken == []
    pngs = sorted(p.relative_to(rep).as_posix() for p in rep.rglob("*.png"))
    page = (rep / "index.html").read_text()
    linked = [p for p in pngs if p in page]
    assert n >= len(linked) > 0  # every figure linked from the page was rendered, and there are some


def test_main_job_report_images_load_in_chromium(tmp_path, chromium):
    """A cheap stage of the real job (the full job runs minutes; see the slow test below)."""
    from benchmarks.mainjob import run_main_job

    rep = tmp_path / "report"
    summary = run_main_job(rep, quick=True, verbose=False, stages=["acoustic sweep"])
    if summary["stages"][0]["status"] != "done":
        pytest.skip(f"acoustic sweep stage did not run: {summary['stages'][0]['message']}")
    _check_report(rep, summary, tmp_path)
    # moving the folder elsewhere keeps it working: paths are relative
    moved = tmp_path / "elsewhere"
    shutil.move(str(rep), moved)
    assert broken_images(moved / "index.html", tmp_path)[1] == []


def test_a_broken_image_is_detected(tmp_path, chromium):
    """The check can fail: a report pointing at a missing PNG is caught."""
    from benchmarks.mainjob import Context, _write_report

    ctx = Context(report_dir=tmp_path / "r", quick=True)
    ctx.figures.append(("missing", "fig/missing.png"))
    index = _write_report(ctx, [])
    n, broken = broken_images(index, tmp_path)
    assert n == 1 and broken == ["fig/missing.png"]


@pytest.mark.slow
def test_full_quick_report_in_chromium(tmp_path, chromium):
    """The whole quick main job: every image of every stage loads."""
    from benchmarks.mainjob import run_main_job

    rep = tmp_path / "report"
    summary = run_main_job(rep, quick=True, verbose=False)
    _check_report(rep, summary, tmp_path)
