"""Unit conversions for human-facing input and output (code and wire are SI)."""

PA_PER_BAR = 1.0e5
