"""Sector-channel designs for the section rung's tests: three annular-sector channels round the
1.5 mm lumen of three_channel_5mm, walls >= 0.5 mm, optionally turned about the body axis."""

from softcath_ros.core.design import design_from_dict, load_design

# the 2-DOF fan design (walls on the 0.5 mm fabrication minimum), shipped in config/designs
THREE_SECTOR_5MM = "three_sector_5mm"


def three_sector(turn: float = 0.0, span: float = 90.0, fillet: float = 0.0, channels: int = 3):
    """Channel i's mid-line at 90 + turn + 120 i degrees (the first ``channels`` of them)."""
    d = load_design("three_channel_5mm").to_dict()
    d["name"] = "three_sector_test"
    d["min_wall_thickness"] = 0.0005
    d["channels"] = [{"shape": "sector", "inner_radius": 0.00125, "outer_radius": 0.002,
                      "direction": 90.0 + turn + 120.0 * i, "span": span, "fillet": fillet} for i in range(channels)]
    return design_from_dict(d)
