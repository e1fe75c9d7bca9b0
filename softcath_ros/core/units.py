"""Unit conversions for human-facing input and output (code and wire are SI)."""

PA_PER_BAR = 1.0e5


def describe_pressure(pa: float) -> str:
    """A pressure (Pa) as ramps and failure messages state it: "p = 0.2518 bar"."""
    return f"p = {pa / PA_PER_BAR:.4f} bar"
