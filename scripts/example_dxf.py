"""Writes docs/examples/d_channel.dxf: a 5 mm section's holes as a CAD program would (units mm).

Layers: CHANNEL, a D-shaped channel (flat side 0.5 mm above the lumen, round side 0.5 mm inside
the outer wall) drawn as a LINE and an ARC; CHANNEL_POLYLINE, the same D as one closed
LWPOLYLINE with a bulge; LUMEN, the 1.5 mm lumen as a CIRCLE; OPEN, an open polyline (refused).
Run: .venv/bin/python scripts/example_dxf.py [OUT.dxf]
"""
import math
import sys
from pathlib import Path

import ezdxf

FLAT_Y = -1.15 + 0.75 + 0.5      # mm: the D's flat side, 0.5 mm above the lumen's top
ROUND_R = 2.5 - 0.5              # mm: the D's round side, 0.5 mm inside the outer wall


def write(out: Path) -> Path:
    doc = ezdxf.new("R2010")
    doc.units = ezdxf.units.MM
    msp = doc.modelspace()
    half = math.sqrt(ROUND_R**2 - FLAT_Y**2)
    a0 = math.degrees(math.atan2(FLAT_Y, half))
    msp.add_line((-half, FLAT_Y), (half, FLAT_Y), dxfattribs={"layer": "CHANNEL"})
    msp.add_arc((0, 0), ROUND_R, a0, 180 - a0, dxfattribs={"layer": "CHANNEL"})
    bulge = math.tan(math.radians(180 - 2 * a0) / 4)
    msp.add_lwpolyline([(half, FLAT_Y, 0, 0, bulge), (-half, FLAT_Y, 0, 0, 0)], format="xyseb", close=True,
                       dxfattribs={"layer": "CHANNEL_POLYLINE"})
    msp.add_circle((0, -1.15), 0.75, dxfattribs={"layer": "LUMEN"})
    msp.add_lwpolyline([(-1, 0.5), (1, 0.5), (0, 1.5)], close=False, dxfattribs={"layer": "OPEN"})
    out.parent.mkdir(parents=True, exist_ok=True)
    doc.saveas(out)
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "docs/examples/d_channel.dxf"
    print(f"wrote {write(target)}")
