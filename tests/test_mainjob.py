"""The main job runs every stage that is built, skips the others with a reason, reports a failed stage and
always writes the report."""

from __future__ import annotations

from benchmarks import mainjob
from benchmarks.cli import main


def test_skipped_and_failed_stages_are_reported(tmp_path, monkeypatch):
    def skipped(ctx):
        raise mainjob.StageSkipped("thing not built yet")

    def broken(ctx):
        raise RuntimeError("boom")

    def fine(ctx):
        from sysid.plots import pyplot

        fig, ax = pyplot().subplots()
        ax.plot([0, 1])
        ctx.save_figure(fig, "ok", "a figure")
        return "made one figure"

    monkeypatch.setattr(mainjob, "STAGES", [("a", skipped), ("b", broken), ("c", fine)])
    out = mainjob.run_main_job(tmp_path / "rep", quick=True, verbose=False)
    st = {s["stage"]: s for s in out["stages"]}
    assert st["a"]["status"] == "skipped" and "not built" in st["a"]["message"]
    assert st["b"]["status"] == "failed" and "boom" in st["b"]["message"]
    assert st["c"]["status"] == "done"
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "fig/ok.png" in page and (tmp_path / "rep" / "fig" / "ok.png").stat().st_size > 0
    assert "RuntimeError" in page
    # the CLI exits 1 when a stage failed, 0 otherwise
    assert main(["run", "--quick", "--report", str(tmp_path / "r2"), "--json"]) == 1
    monkeypatch.setattr(mainjob, "STAGES", [("a", skipped), ("c", fine)])
    assert main(["run", "--quick", "--report", str(tmp_path / "r3"), "--json"]) == 0
