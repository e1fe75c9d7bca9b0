"""`softcath recover FILE.mcap`: rebuild a truncated recording, keeping every complete message."""
from __future__ import annotations

import sys

from ..core import json_output


def register(sub) -> None:
    p = sub.add_parser("recover", help="rebuild a truncated MCAP recording (recorder killed, power lost)")
    p.add_argument("file", help="the .mcap file (or its bag directory)")
    p.add_argument("--output", default=None,
                   help="write the recovered file here (default: in place; the damaged original is kept in "
                        "<bag>.damaged/ beside the bag folder, or as FILE.truncated outside a bag folder)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..recording.reader import recording_file
    from ..recording.recover import recover

    report = recover(recording_file(args.file), args.output)
    if args.json:
        json_output.dump(report.to_json(), sys.stdout, indent=2)
        print()
        return 0
    state = "was complete" if report.was_complete else f"was truncated ({report.stop_reason or 'cut'})"
    print(f"{report.source} {state}: kept {report.messages} messages in {report.chunks} chunks"
          + (f", dropped {report.dropped_chunks} damaged chunk(s)" if report.dropped_chunks else ""))
    for topic, n in sorted(report.per_topic.items()):
        print(f"  {topic}: {n}")
    print(f"recovered recording: {report.output}")
    if report.damaged_original:
        print(f"damaged original:    {report.damaged_original}")
    return 0
