"""Feed a running model_node a pressure sweep and collect its predicted poses.

    python -m softcath_ros.tools.pressure_sweep --from 0 --to 0.35bar --steps 8 --plot runs/x.png

Sends one command at a time on /softcath/pressure_cmd and waits for the node's
/softcath/tip_pose and /softcath/backbone answer before the next one (lock-step, so
every pose belongs to a known command). The bending angle is the received backbone's tangent
turning integrated from base to tip (core.kinematics.backbone_bend_angle: right past 180 degrees,
where the tip orientation alone folds back) and 1/|k| comes from the tip position
(core.kinematics.curvature_for_tip, with the design's straight tip cap), so the table shows what
the topics say, not a second computation. Reusable: ``SweepClient.run(pressures)``.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import topics
from ..cli.common import add_unit_argument, bounded_int, finite_float, parse_pressure, positive_float
from ..core import json_output
from ..core.errors import SoftcathError
from ..core.kinematics import radius_l_over_theta
from ..core.units import PA_PER_BAR
from ..graph import default_to_localhost_discovery


@dataclass
class SweepPoint:
    pressures_pa: list[float]
    tip_position_m: list[float]
    tip_orientation_xyzw: list[float]
    backbone_m: list[list[float]]       # (points, 3) positions, base to tip
    stamp_ns: int
    backbone_orientation_xyzw: list[list[float]] = field(default_factory=list)   # (points, 4), base to tip

    def radius_and_angle(self, cap: float = 0.0) -> tuple[float, float]:
        """(1/|k| in m of the arc that ends ``cap`` (m, the straight tip cap) before the tip, inf when
        straight; bending angle theta in rad, the backbone's integrated tangent turning, or without a
        backbone the tip orientation's rotation, which folds back past 180 degrees). R_C = l / theta
        needs the sample's unstretched length l (``print_table``)."""
        from ..core.kinematics import backbone_bend_angle, curvature_for_tip

        inv = curvature_for_tip(np.array(self.tip_position_m), cap=cap)
        kappa = float(np.hypot(*inv.curvature))
        quats = self.backbone_orientation_xyzw if len(self.backbone_orientation_xyzw) >= 2 else \
            [[0.0, 0.0, 0.0, 1.0], self.tip_orientation_xyzw]
        return (1.0 / kappa if kappa > 0 else math.inf), backbone_bend_angle(quats)


class SweepClient:
    """A small rclpy node that sends commands and waits for the model node's answers."""

    def __init__(self, node_name: str = "softcath_sweep", timeout_s: float = 5.0, context=None):
        import rclpy
        from geometry_msgs.msg import PoseArray, PoseStamped
        from rclpy.executors import SingleThreadedExecutor
        from std_msgs.msg import Float64MultiArray

        from ..nodes.qos import stream_qos

        self._msg_type = Float64MultiArray
        self.node = rclpy.create_node(node_name, context=context)
        self.timeout_s = timeout_s
        qos = stream_qos(100)
        self._tips: list = []
        self._backbones: list = []
        self._tip_sub = self.node.create_subscription(PoseStamped, topics.TIP_POSE, self._tips.append, qos)
        self._bb_sub = self.node.create_subscription(PoseArray, topics.BACKBONE, self._backbones.append, qos)
        self._pub = self.node.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, qos)
        self._executor = SingleThreadedExecutor(context=context)
        self._executor.add_node(self.node)

    def spin_until(self, done, timeout_s: float) -> bool:
        """Run callbacks until ``done()`` is true (True) or ``timeout_s`` passes (False)."""
        end = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > end:
                return False
            self._executor.spin_once(timeout_sec=0.02)
        return True

    def wait_for_model_node(self, timeout_s: float = 20.0, probe=None) -> None:
        """Wait until a model node is matched both ways. With ``probe`` (a command, Pa), also until it
        answers that command: DDS reports a match before the first message is sure to arrive, so the
        probe is re-sent every 0.5 s until an answer comes (the sweep's first command is a good probe:
        the node answers its repeat from its last answer)."""
        end = time.monotonic() + timeout_s
        ok = self.spin_until(lambda: (self._pub.get_subscription_count() > 0 and self._tip_sub.get_publisher_count() > 0
                                       and self._bb_sub.get_publisher_count() > 0), timeout_s)
        while ok and probe is not None:
            if self.send(probe, timeout_s=min(0.5, max(end - time.monotonic(), 0.0))) is not None:
                break
            ok = time.monotonic() < end
        if not ok:
            raise TimeoutError(f"no model_node on /softcath/pressure_cmd after {timeout_s:g} s" if probe is None else
                               f"model_node did not answer the first command within {timeout_s:g} s "
                               "(refused? its /diagnostics say why)")
        self.spin_until(lambda: False, 0.3)  # a late answer to a repeated probe is taken here, not by the sweep

    @property
    def n_received(self) -> int:
        """Tip poses received so far."""
        return len(self._tips)

    def send(self, pressures_pa, timeout_s: float | None = None) -> SweepPoint | None:
        """Publish one command; the node's answer, or None if none came within the timeout."""
        n_tip, n_bb = len(self._tips), len(self._backbones)
        self._pub.publish(self._msg_type(data=[float(p) for p in pressures_pa]))
        if not self.spin_until(lambda: len(self._tips) > n_tip and len(self._backbones) > n_bb,
                               self.timeout_s if timeout_s is None else timeout_s):
            return None
        tip, bb = self._tips[n_tip], self._backbones[n_bb]
        p, q = tip.pose.position, tip.pose.orientation
        return SweepPoint(pressures_pa=[float(v) for v in pressures_pa], tip_position_m=[p.x, p.y, p.z],
                          tip_orientation_xyzw=[q.x, q.y, q.z, q.w],
                          backbone_m=[[b.position.x, b.position.y, b.position.z] for b in bb.poses],
                          backbone_orientation_xyzw=[[b.orientation.x, b.orientation.y, b.orientation.z,
                                                      b.orientation.w] for b in bb.poses],
                          stamp_ns=tip.header.stamp.sec * 1_000_000_000 + tip.header.stamp.nanosec)

    def run(self, commands) -> list[SweepPoint | None]:
        return [self.send(c) for c in commands]

    def close(self) -> None:
        self._executor.shutdown()
        self.node.destroy_node()


def sweep_commands(start: float, stop: float, steps: int, n_channels: int, channel: int) -> np.ndarray:
    """(steps, n_channels) Pa: ``channel`` ramps from ``start`` to ``stop``, the others stay at 0."""
    p = np.zeros((steps, n_channels))
    p[:, channel] = np.linspace(start, stop, steps)
    return p


def print_table(points: list[SweepPoint | None], commands, length: float, cap: float = 0.0, file=sys.stdout) -> None:
    """One line per command: R_C = l / theta (``length`` l and the tip ``cap`` in m, the design's), 1/|k|,
    angle, tip."""
    print(f"{'pressure [bar]':>16} {'R_C=l/theta [mm]':>17} {'1/|k| [mm]':>11} {'angle [deg]':>12} "
          f"{'tip x, y, z [mm]':>28}", file=file)
    for cmd, pt in zip(commands, points):
        ps = ",".join(f"{v / PA_PER_BAR:.3f}" for v in cmd)
        if pt is None:
            print(f"{ps:>16}  no pose (rejected by the node or timed out; see /diagnostics)", file=file)
            continue
        centreline, angle = pt.radius_and_angle(cap)
        tip = ", ".join(f"{v * 1e3:7.2f}" for v in pt.tip_position_m)
        rc = radius_l_over_theta(length, angle)
        rc_s = "inf" if math.isinf(rc) else f"{rc * 1e3:.2f}"
        k_s = "inf" if math.isinf(centreline) else f"{centreline * 1e3:.2f}"
        print(f"{ps:>16} {rc_s:>17} {k_s:>11} {math.degrees(angle):12.2f} {tip:>28}", file=file)


def plot_backbones(points: list[SweepPoint | None], path: Path, title: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    good = [p for p in points if p is not None]
    cmap = plt.get_cmap("viridis")
    pmax = max((max(p.pressures_pa) for p in good), default=1.0) or 1.0
    for p in good:
        b = np.asarray(p.backbone_m) * 1e3
        ax.plot(b[:, 1], b[:, 2], color=cmap(max(p.pressures_pa) / pmax),
                label=f"{max(p.pressures_pa) / PA_PER_BAR:.3f} bar")
        ax.plot(b[-1, 1], b[-1, 2], "o", color=cmap(max(p.pressures_pa) / pmax), ms=3)
    ax.set_aspect("equal")
    ax.set_xlabel(f"y [mm] ({topics.FRAME_ID})")
    ax.set_ylabel("z [mm]")
    ax.set_title(title or "predicted backbones from /softcath/backbone")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def build_parser() -> argparse.ArgumentParser:
    from ..cli import OneLineParser

    ap = OneLineParser(prog="pressure_sweep", description="send a pressure sweep to a running model_node and show "
                       "its poses")
    ap.add_argument("--from", dest="start", default="0", help="first pressure, e.g. 0.05bar (default 0)")
    ap.add_argument("--to", dest="stop", default="0.35bar", help="last pressure, e.g. 0.25bar (default 0.35bar)")
    ap.add_argument("--steps", type=bounded_int(1, 10_000), default=8)
    add_unit_argument(ap, "--from/--to")
    ap.add_argument("--channels", type=bounded_int(1, 64), default=1, help="channels of the node's design")
    ap.add_argument("--length", type=positive_float, default=0.040,
                    help="the node's design length in m, for R_C = l / theta (default 0.040: implemented_5mm)")
    ap.add_argument("--cap", type=finite_float, default=0.001,
                    help="the design's tip cap in m, straight beyond the bent arc (default 0.001: implemented_5mm)")
    ap.add_argument("--channel", type=bounded_int(0, 63), default=0, help="channel that is swept")
    ap.add_argument("--plot", type=Path, default=None, help="PNG of the backbones")
    ap.add_argument("--json", type=Path, default=None, help="write the sweep points as JSON here")
    ap.add_argument("--timeout", type=positive_float, default=5.0, help="s to wait for each answer")
    ap.add_argument("--wait", type=positive_float, default=30.0, help="s to wait for model_node to answer (default 30)")
    return ap


def sweep_range(args) -> tuple[float, float]:
    """(--from, --to) in Pa by the one pressure rule (core/units.py); SoftcathError otherwise."""
    start, stop = parse_pressure(args.start, "--from", args.unit), parse_pressure(args.stop, "--to", args.unit)
    if start < 0 or stop < 0:
        raise SoftcathError("--from/--to are gauge pressures and must not be negative")
    return start, stop


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.steps < 1 or not 0 <= args.channel < args.channels:
        ap.error("need --steps >= 1 and 0 <= --channel < --channels")
    if not 0.0 <= args.cap < args.length:
        ap.error(f"--cap {args.cap} m must be in [0, --length {args.length} m)")
    try:
        start, stop = sweep_range(args)
    except SoftcathError as exc:
        ap.error(str(exc))
    commands = sweep_commands(start, stop, args.steps, args.channels, args.channel)

    import rclpy

    default_to_localhost_discovery()
    rclpy.init()
    client = None
    try:
        client = SweepClient(timeout_s=args.timeout)
        client.wait_for_model_node(args.wait, probe=commands[0])
        points = client.run(commands)
    except TimeoutError as exc:
        print(f"pressure_sweep: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("pressure_sweep: interrupted", file=sys.stderr)
        return 130
    finally:
        if client is not None:
            client.close()
        rclpy.try_shutdown()
    print_table(points, commands, args.length, args.cap)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json_output.dumps([p.__dict__ if p else None for p in points], indent=1))
    if args.plot:
        print(f"backbone plot: {plot_backbones(points, args.plot)}")
    return 0 if all(p is not None for p in points) else 1


if __name__ == "__main__":
    sys.exit(main())
