"""The shipped envelope is what `softcath envelope` writes from the committed ladder results:
the same rows give the same file, byte for byte, apart from the date, load and provenance note
the command stamps when it writes."""
import json
from pathlib import Path

import pytest
import yaml

from softcath_ros.core.ladder_envelope import write_envelope
from softcath_ros.resources import envelope_path

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "ladder_chart.json"


@pytest.mark.skipif(not RESULTS.is_file(), reason="the committed ladder results (source checkout only)")
def test_committed_results_give_the_shipped_envelope(tmp_path):
    rows = json.loads(RESULTS.read_text())["results"]
    out = tmp_path / "ladder_envelope.yaml"
    write_envelope(rows, out)
    written, shipped = out.read_text(), envelope_path().read_text()
    assert list(yaml.safe_load(written)) == list(yaml.safe_load(shipped))   # same keys, same order
    # everything from the per-rung envelopes on is identical text; above it only date, load and note differ
    assert written[written.index("\nrungs:\n"):] == shipped[shipped.index("\nrungs:\n"):]
    head = {k: v for k, v in yaml.safe_load(written).items() if k != "rungs"}
    assert head.keys() == {"reference", "measured", "loadavg", "note"}
    assert head["reference"] == yaml.safe_load(shipped)["reference"]


@pytest.mark.skipif(not RESULTS.is_file(), reason="the committed ladder results (source checkout only)")
def test_keep_re_measures_some_cases_and_keeps_the_others_rows(tmp_path, monkeypatch, capsys):
    """`softcath envelope --cases C --keep RESULTS.json`: C measured now, every other case's rows as
    they were (their fe3d took hours), all in the ladder's order; the envelope is the merged rows'."""
    from softcath_ros.cli import main as softcath
    from softcath_ros.core import ladder
    from softcath_ros.core.ladder_envelope import envelope_document

    committed = json.loads(RESULTS.read_text())
    measured_now = "sector one channel"
    fresh = [{**r, "s_per_eval": 1.0} for r in committed["results"] if r["case"] == measured_now]
    assert fresh
    monkeypatch.setattr(ladder, "run_case", lambda case, *a, **k: (fresh, "section D/20"))
    out, stem = tmp_path / "env.yaml", tmp_path / "rows"
    assert softcath(["envelope", "--out", str(out), "--results", str(stem), "--cases", measured_now,
                     "--keep", str(RESULTS)]) == 0
    written = json.loads(stem.with_suffix(".json").read_text())
    expected = [r if r["case"] != measured_now else {**r, "s_per_eval": 1.0} for r in committed["results"]]
    assert written["results"] == expected
    kept = [c for c in dict.fromkeys(r["case"] for r in expected) if c != measured_now]
    assert written["meta"]["kept"]["cases"] == kept
    # each kept case keeps when it was measured; the case measured now has this run's commit and date
    assert {c: written["meta"]["measured"][c] for c in kept} == {c: committed["meta"]["measured"][c] for c in kept}
    assert written["meta"]["measured"][measured_now]["date"] == written["meta"]["date"]
    assert [c["name"] for c in written["meta"]["cases"]] == [c.name for c in ladder.CASES]
    assert yaml.safe_load(out.read_text())["rungs"] == json.loads(json.dumps(envelope_document(expected, "x")["rungs"]))
    assert "(from a subset" not in capsys.readouterr().out


def test_keep_refuses_a_file_that_is_not_ladder_results_in_one_line(tmp_path, capsys):
    from softcath_ros.cli import main as softcath

    bad = tmp_path / "bad.json"
    for text, match in (("{}", "not results written by --results"),
                        ('{"meta": {}, "results": [{"case": "2ch 10mm"}]}', "are not ladder cases")):
        bad.write_text(text)
        assert softcath(["envelope", "--out", str(tmp_path / "e.yaml"), "--cases", "1ch 40mm", "--keep", str(bad)]) == 2
        err = capsys.readouterr().err.strip()
        assert match in err and len(err.splitlines()) == 1
    assert softcath(["envelope", "--cases", "1ch 40mm", "--keep", str(tmp_path / "none.json")]) == 2
    assert "--keep" in capsys.readouterr().err
