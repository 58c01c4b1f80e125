"""The main job runs every stage that is built, skips the others with a reason, reports a failed stage and
always writes the report; it scores at budgets whose floors exist, judges each row against the floor measured at
the same budget (or says it did not), and names what it left to `piezotwin records` and `piezotwin score`."""

from __future__ import annotations

import json

import pytest

from benchmarks import mainjob, mainjob_score, scoring
from benchmarks.cli import main
from benchmarks.records import RECORDS_JSON


def test_skipped_and_failed_stages_are_reported(tmp_path, monkeypatch):
    def skipped(ctx):
        raise mainjob.StageSkipped("thing not built yet")

    def broken(ctx):
        raise RuntimeError("boom")

    def fine(ctx):
        from sysid.report.plots import pyplot

        fig, ax = pyplot().subplots()
        ax.plot([0, 1])
        ctx.save_figure(fig, "ok", "a figure")
        ctx.leave("a long thing", "takes an hour", "piezotwin records --datasets x")
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
    # the header says how long the run took and names what it left, with the command
    assert "The run took 0 min" in page and "a long thing" in page and "piezotwin records --datasets x" in page
    assert out["left"] == [
        {"what": "a long thing", "why": "takes an hour", "command": "piezotwin records --datasets x"}
    ]
    # the CLI exits 1 when a stage failed, 0 otherwise
    assert main(["run", "--quick", "--report", str(tmp_path / "r2"), "--json"]) == 1
    monkeypatch.setattr(mainjob, "STAGES", [("a", skipped), ("c", fine)])
    assert main(["run", "--quick", "--report", str(tmp_path / "r3"), "--json"]) == 0


def test_every_scored_dataset_has_floors_at_the_budget_it_is_scored_at():
    """The scoring stages score the quick check's datasets at its budgets: the quick floors judge every row."""
    floors = scoring.load_baselines()["modes"]["quick"]
    floored = {d for per_ident in floors.values() for d in per_ident}
    for quick in (False, True):
        p = mainjob_score.plan(quick)
        assert p["twins"] and p["lab"]
        assert set(p["twins"] + p["lab"]) <= set(scoring.QUICK_DATASETS) & floored
    assert set(mainjob_score.plan(False)["lab"]) == set(scoring.QUICK_DATASETS) - set(
        mainjob_score.plan(False)["twins"]
    )


def test_one_seed_is_judged_by_floors_that_cover_every_single_seed():
    """The main job trains seeded identifiers once (seed 0); a quick floor of a seeded pair is at least its worst
    single seed x (1 + margin), so seed 0 alone below its floor is what the floor promises."""
    base = scoring.load_baselines()
    seeded = [
        f
        for per_ident in base["modes"]["quick"].values()
        for tests in per_ident.values()
        for f in tests.values()
        if "worst_single_seed" in f
    ]
    assert len(seeded) >= 20
    assert 0 in mainjob_score.MAIN_SEEDS and set(mainjob_score.MAIN_SEEDS) <= set(scoring.QUICK_SEEDS)
    for f in seeded:
        assert f["max_rmse"] >= f["worst_single_seed"] * (1 + scoring.DEFAULT_MARGIN) * (1 - 1e-3), (
            f
        )  # stored to 4 digits


def test_rows_without_a_floor_at_their_budget_are_not_compared():
    base = {
        "modes": {"quick": {"arx": {"silverbox": {"multisine": {"max_rmse": 0.01}}}}},
        "dropped": {"quick": [{"identifier": "oe", "dataset": "silverbox", "reason": "r"}]},
    }
    rows = [
        {"identifier": "arx", "dataset": "silverbox", "test": "multisine"},
        {"identifier": "arx", "dataset": "silverbox", "test": "arrow"},
        {"identifier": "oe", "dataset": "silverbox", "test": "arrow"},
        {"identifier": "arx", "dataset": "cantilever-thesis-clean", "test": "thesis-sines"},
    ]
    assert scoring.unfloored({"mode": "quick", "rows": rows}, base) == [
        ("arx", "silverbox", "arrow"),
        ("arx", "cantilever-thesis-clean", "thesis-sines"),
    ]


def test_stored_records_are_shown_as_stored_with_date_machine_and_command(tmp_path):
    stored = json.loads(RECORDS_JSON.read_text(encoding="utf-8"))
    ctx = mainjob.Context(report_dir=tmp_path, quick=False)
    assert mainjob_score.stored_records(ctx) == len(stored) >= 5
    title, html = ctx.sections[-1]
    assert "stored" in title and "not recomputed" in title
    for e in stored.values():
        assert e["command"] in html and e["measured"]["date"] in html
        assert e["measured"]["machine"]["cpu"] in html
    assert [c for _, _, c in ctx.left] == [f"piezotwin records --datasets {d}" for d in stored]


def test_scoring_stage_judges_rows_against_quick_floors(tmp_path, monkeypatch):
    """ARX alone (a few seconds): its cascaded-tanks row meets its quick floor; the same identifier on a dataset
    without quick floors is shown as not compared, never as below floor."""
    import sysid.registry

    monkeypatch.setattr(sysid.registry, "available_identifiers", lambda: ["arx"])
    monkeypatch.setattr(scoring, "write_report", lambda run, folder: {})  # the figures are not what is tested here
    ctx = mainjob.Context(report_dir=tmp_path, quick=True, verbose=False)
    msg = mainjob_score._score_stage(ctx, ["cascaded-tanks"], "lab", "lab", sysidentpy=False)
    assert "1 compared with quick floors, 0 below floor" in msg, msg
    assert ctx.data["lab_check"] == [] and ctx.data["lab_not_compared"] == []
    msg = mainjob_score._score_stage(ctx, ["acoustic-thesis-clean"], "twins", "twins", sysidentpy=False)
    assert "0 compared with quick floors, 0 below floor, 1 without a floor at this budget (not compared)" in msg, msg
    assert mainjob.floor_counts(ctx) == {"compared": 1, "below_floor": 0, "not_compared": 1}


@pytest.mark.slow
def test_quick_main_job_meets_its_floors(tmp_path):
    """The whole `run --quick`: every stage done, no row below its floor, the stored rows named."""
    out = mainjob.run_main_job(tmp_path / "rep", quick=True, verbose=False)
    assert all(s["status"] == "done" for s in out["stages"]), out["stages"]
    assert out["below_floor"] == 0 and out["compared"] > 0
    assert any(x["command"].startswith("piezotwin records") for x in out["left"])
