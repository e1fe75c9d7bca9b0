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
