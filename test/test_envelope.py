"""The shipped envelope is what `softcath envelope` writes from the committed ladder results:
the same rows give the same file, byte for byte, apart from the date, load and provenance note
the command stamps when it writes."""
import json
from pathlib import Path

import pytest
import yaml

from softcath_ros.core.ladder import envelope_document
from softcath_ros.resources import envelope_path

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "ladder_chart.json"


@pytest.mark.skipif(not RESULTS.is_file(), reason="the committed ladder results (source checkout only)")
def test_committed_results_give_the_shipped_envelope():
    rows = json.loads(RESULTS.read_text())["results"]
    shipped_text = envelope_path().read_text()
    shipped = yaml.safe_load(shipped_text)
    doc = envelope_document(rows, shipped["measured"])
    assert list(doc) == list(shipped) and doc["rungs"] == shipped["rungs"]
    doc["loadavg"], doc["note"] = shipped["loadavg"], shipped["note"]
    assert yaml.safe_dump(doc, sort_keys=False) == shipped_text
