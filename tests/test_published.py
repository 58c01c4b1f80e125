"""Published results as data (benchmarks/settings/published.toml): the scoring references and the records page
take their numbers from the file, each with its source; the baselines table puts the paper's number (or "not
read") beside the project's stored measurement; a malformed file is refused with one line."""

from __future__ import annotations

import copy
import tomllib

import pytest

from benchmarks import published, records
from benchmarks.datasets.references import references_for
from sysid.errors import ConfigError

DOC = published.load()


def test_references_are_the_files_numbers_in_the_datasets_units():
    n = 0
    for dname, tests in DOC["references"].items():
        for test, kinds in tests.items():
            for kind, e in kinds.items():
                ref = references_for(dname)[test][kind]
                factor = {"mV": 1e-3}.get(e["unit"], 1.0)
                assert ref["value"] == pytest.approx(e["value"] * factor, rel=1e-12) and ref["model"] == e["model"]
                assert ref["unit"] == ("V" if e["unit"] == "mV" else e["unit"])
                n += 1
    assert n >= 15
    # the full arrow's record is PNLSS's 0.26 mV (not SUBNET's 1.41 mV), the tanks' a grey box's 0.191 V
    assert references_for("silverbox")["arrow"]["best_published"]["value"] == 0.26e-3
    best = published.best_published("silverbox", "arrow")
    assert best["source"] == "Paduart et al. 2010 in Champneys et al. 2024" and "2405.10779" not in best["source"]
    assert "quoting Champneys et al. 2024" in best["read_from"]
    assert references_for("cascaded-tanks")["test"]["best_published"]["model"] == "grey-box"
    assert references_for("cascaded-tanks")["test"]["best_published_black_box"]["value"] == 0.34


def test_committed_page_shows_every_best_published_number_of_the_file_with_its_source():
    page = records.MARKDOWN_PATH.read_text(encoding="utf-8")
    entries = {e.dataset for e in records.load_entries()}
    for dname, tests in DOC["references"].items():
        for test, kinds in tests.items():
            e = kinds.get("best_published")
            if e is None or dname not in entries:
                continue
            best = published.best_published(dname, test)
            line = f"| {dname}, {test} | {e['value']:g} {e['unit']} | {e['model']} | {best['cite']} | "
            assert line in page, line


def _doc_with_values() -> dict:
    doc = copy.deepcopy(DOC)
    doc["baselines"]["values"] = {
        "silverbox": {"multisine": {"unit": "mV", "ARX": 1.5, "GRU": 0.75}},
        "cascaded-tanks": {"test-official": {"unit": "V", "ARX": 0.6}},
    }
    published._validate(doc, published.PUBLISHED_PATH)
    return doc


def test_baselines_table_puts_each_number_in_its_cell():
    floors = {
        "arx": {"silverbox": {"multisine": {"measured": 9.0e-3, "measured_min": 8.0e-3, "runs": 2}}},
        "rnn": {"silverbox": {"multisine": {"measured": 2.3e-3}}},
    }
    text = published.baselines_text(records.fmt_value, floors, doc=_doc_with_values())
    assert text["tests"][0] == "silverbox / multisine" and text["tests"][-1] == "cascaded-tanks / test-official"
    by = {r["family"]: r for r in text["rows"]}
    assert [r["family"] for r in text["rows"]] == [f["name"] for f in DOC["baselines"]["families"]]
    assert by["ARX"]["identifier"] == "`arx`" and by["ARX"]["cells"][0] == "1.50 mV · 8.00 mV–9.00 mV"
    assert by["ARX"]["cells"][-1] == "0.600 V · not measured"  # no floor given for the pair
    assert by["ARX"]["cells"][1] == "not read · not measured"
    assert by["GRU"]["cells"][0] == "0.750 mV · 2.30 mV"
    assert by["GP-NARX"]["identifier"] == "—" and by["GP-NARX"]["cells"][0] == "not read · —"
    # the LSTM family is `rnn` with another cell: the GRU's floor is not its measurement
    assert by["LSTM"]["identifier"] == "`rnn` (cell=lstm)" and by["LSTM"]["cells"][0] == "not read · not measured"


def test_committed_page_has_the_baselines_table_with_the_stored_measurements():
    page = records.MARKDOWN_PATH.read_text(encoding="utf-8")
    from benchmarks.scoring.floors import load_baselines

    text = published.baselines_text(records.fmt_value, load_baselines()["modes"]["full"])
    assert "**The ten baselines of Champneys et al. 2024**" in page
    for r in text["rows"]:
        assert f"| {r['family']} | {r['identifier']} | " + " | ".join(r["cells"]) + " |" in page
    arx = next(r for r in text["rows"] if r["family"] == "ARX")
    assert arx["cells"][0].endswith("· 9.05 mV")  # ARX's full floor on Silverbox multisine, benchmarks/baselines.json


@pytest.mark.parametrize(
    "edit, expected",
    [
        (lambda d: d["references"]["silverbox"]["arrow"]["best_published"].update(unit="mm"), "unit 'mm' unknown"),
        (lambda d: d["references"]["silverbox"]["arrow"]["best_published"].update(value=-1.0), "finite positive"),
        (lambda d: d["references"]["silverbox"]["arrow"]["best_published"].update(source="nobody"), "not defined"),
        (lambda d: d["references"]["silverbox"]["arrow"]["best_published"].pop("read_from"), "needs exactly"),
        (lambda d: d["references"]["silverbox"]["arrow"].update(best_ever={}), "unknown kind"),
        (lambda d: d["baselines"]["values"].update(silverbox={"multisine": {"unit": "mV", "XGB": 1.0}}), "XGB"),
        (lambda d: d["baselines"]["values"].update(silverbox={"sine": {"unit": "mV", "ARX": 1.0}}), "baselines.tests"),
        (lambda d: d["baselines"]["families"][0].update(identifier="lti"), "unknown identifier"),
        (lambda d: d["sources"]["paduart2010"].pop("short"), "needs `short`"),
    ],
)
def test_a_malformed_file_is_refused_with_one_line(edit, expected):
    doc = copy.deepcopy(DOC)
    edit(doc)
    with pytest.raises(ConfigError, match=expected) as exc:
        published._validate(doc, published.PUBLISHED_PATH)
    assert "\n" not in str(exc.value)


def test_a_file_that_is_not_toml_is_refused(tmp_path):
    bad = tmp_path / "published.toml"
    bad.write_text("[sources\n")
    with pytest.raises(ConfigError, match="cannot be read"):
        published.load(bad)
    with pytest.raises(tomllib.TOMLDecodeError):
        tomllib.loads(bad.read_text())
