"""scale_node (node ``softcath_scale``): a serial load cell (HX711-class board, the line protocol of
bench/hardware/protocol.py: ``F <newtons>`` lines, host ``TARE``) as the rig contract's scale
(docs/rig.md, docs/lab.md). A managed (lifecycle) node around ``softcath_ros.bench.hardware.scale``:

- configure: opens the port and one valid reading must come within ``check_timeout``;
- activate: publishes each new reading on /softcath/bench/wrench (geometry_msgs/WrenchStamped,
  ``wrench.force.z`` in N, frame softcath_scale), stamped when it was read from the port; a line
  it refuses (malformed, NaN, beyond ``max_force``) is counted on /diagnostics, never published;
- a message on /softcath/bench/tare (std_msgs/Empty) sends ``TARE``: the board zeroes at the
  present load;
- no valid reading for ``silence_timeout`` (0.4 s): ERROR on /diagnostics at once, until valid
  readings come again (then WARN with the count of silences: the core's docstring says why).
"""
from __future__ import annotations

import sys
import time
from functools import partial

from geometry_msgs.msg import WrenchStamped
from std_msgs.msg import Empty

from .. import topics
from ..bench.hardware.devices import SerialLines
from ..bench.hardware.scale import Scale
from ..core.errors import SoftcathError
from .device_node import DeviceNode
from .diagnostics import diagnostic_status, publish_statuses
from .parameters import declare
from .runtime import run_node


class ScaleNode(DeviceNode):

    def __init__(self, **node_options):
        super().__init__(topics.SCALE_NODE, **node_options)
        p = partial(declare, self)
        self.declare_serial("/dev/ttyUSB0")
        self.max_force = p("max_force", 5.0, "the cell's capacity, N: a reading beyond +-this is refused",
                           minimum=1e-3, maximum=1e5)
        self.rate_hz = p("rate_hz", 100.0, "port polls per second (each publishes the newest reading)",
                         minimum=20.0, maximum=1000.0)
        self.declare_checks("ERROR", "a reading must come")
        self.create_subscription(Empty, topics.BENCH_TARE, self.on_tare, 10)
        self.start()

    def make_core(self) -> Scale:
        return Scale(SerialLines(self.port, self.baud, "F", 1, -self.max_force, self.max_force), time.monotonic,
                     check_timeout=self.check_timeout, silence_timeout=self.silence_timeout)

    def make_publishers(self) -> list:
        return [self.create_lifecycle_publisher(WrenchStamped, topics.BENCH_WRENCH, 10)]

    def on_tare(self, msg) -> None:
        if self.core is None or not self.core.tare():
            self.get_logger().warning("tare ignored: the scale is not configured")
        else:
            self.get_logger().info("tare sent")

    def tick(self) -> None:
        r = self.core.tick()
        if r is not None:
            w = WrenchStamped()
            w.header.stamp, w.header.frame_id = self.get_clock().now().to_msg(), topics.SCALE_FRAME_ID
            w.wrench.force.z = r.value
            self.pubs[0].publish(w)

    def diagnostics(self) -> None:
        s = self.core
        level, message = self.level_and_message([] if s is None else [
            s.counters.refused and f"{s.counters.refused} line(s) refused, last {s.counters.last_refused}",
            s.counters.device_errors and f"device error: {s.counters.last_device_error}",
            s.silences and f"{s.silences} silence(s), the last: {s.last_silence}"])
        values = [("state", self.state_name), ("port", self.port)]
        if s is not None:
            values += [("readings", s.counters.readings), ("refused", s.counters.refused),
                       ("device_errors", s.counters.device_errors), ("tares", s.tares),
                       ("silences", s.silences)]
        publish_statuses(self, self.pub_diag, diagnostic_status(level, topics.SCALE_NODE, message, values,
                                                                hardware_id=f"serial:{self.port}"))


def main(args=None) -> int:
    return run_node(ScaleNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
