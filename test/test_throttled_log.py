"""Warnings about bad inputs are throttled before rclpy is called (rclpy's own throttle looks up the
caller's source file first, 0.2-0.3 ms a call: a stream of refused commands at 1 kHz would pay it on
every one)."""
from softcath_ros.nodes.diagnostics import ThrottledLog


class _Logger:
    def __init__(self):
        self.lines = []

    def warning(self, text):
        self.lines.append(("warning", text))

    def error(self, text):
        self.lines.append(("error", text))


def test_one_line_per_period_per_call_site_and_none_in_between():
    now = [100.0]
    logger = _Logger()
    log = ThrottledLog(logger, 1.0, clock=lambda: now[0])
    for i in range(1000):                      # 1 kHz for one second: the first of each site only
        now[0] = 100.0 + i * 1e-3
        log.warning("rejected", f"rejected {i}")
        log.error("model_failed", f"failed {i}")
    assert logger.lines == [("warning", "rejected 0"), ("error", "failed 0")]
    now[0] = 101.0                             # a period after the first: the next one is said
    log.warning("rejected", "rejected again")
    log.warning("clamped", "clamped")          # another site has its own period
    assert logger.lines[2:] == [("warning", "rejected again"), ("warning", "clamped")]
