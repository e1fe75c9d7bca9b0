"""Every topic the suite publishes or subscribes, with its message type, in one place.

Plain strings (no ROS import), so the nodes, the recorder, the command line, the tests and the
benchmarks name topics the same way. Units and frames: docs/nodes.md.
"""
from __future__ import annotations

PRESSURE_CMD = "/softcath/pressure_cmd"            # commanded gauge pressure per channel, Pa
PRESSURE_MEASURED = "/softcath/pressure_measured"  # measured gauge pressure per channel, Pa
TIP_POSE = "/softcath/tip_pose"                    # predicted tip pose in softcath_base
BACKBONE = "/softcath/backbone"                    # predicted backbone poses, base to tip
BEND_CMD = "/softcath/bend_cmd"                    # desired curvature vector (x, y), 1/m
TIP_TARGET = "/softcath/tip_target"                # desired tip position, m
BENCH_ANGLE = "/softcath/bench/angle"              # DEPRECATED (unstamped): measured bending angle, rad
BENCH_FORCE = "/softcath/bench/force"              # DEPRECATED (unstamped): measured blocking force, N
# The rig contract (docs/rig.md): stamped measurements from the standard message packages.
PRESSURE_MEASURED_CHANNEL = "/softcath/pressure_measured/ch{channel}"  # one FluidPressure per channel, Pa
BENCH_BEND_ANGLE = "/softcath/bench/bend_angle"    # measured bending angle (vector.x), rad
BENCH_TARE = "/softcath/bench/tare"                # std_msgs/Empty: zero the scale (scale_node)
BENCH_WRENCH = "/softcath/bench/wrench"            # scale reading (force.z), N, frame SCALE_FRAME_ID
TIP_TRUE = "/softcath/bench/tip_true"              # simulated rig only: the true tip pose, for scoring
BENCH_STEP = "/softcath/bench/step"                # protocol markers (JSON)
BENCH_RIG = "/softcath/bench/rig"                  # the rig announces itself (JSON, transient local)
BODY_MARKER = "/softcath/body_marker"              # live 3D view: the body as a triangle list
BACKBONE_PATH = "/softcath/backbone_path"          # live 3D view: the backbone as a path
RADIUS_L_OVER_THETA = "/softcath/radius_l_over_theta"  # predicted R_C = l / theta, m
TIP_MEASURED = "/softcath/tip_measured"            # measured tip pose in softcath_base (a tracker)
DIAGNOSTICS = "/diagnostics"
READY = "/softcath/ready"  # each node once it spins: JSON {node, pid, executor} (transient local; graph.py waits)

MESSAGE_TYPES = {
    PRESSURE_CMD: "std_msgs/msg/Float64MultiArray",
    PRESSURE_MEASURED: "std_msgs/msg/Float64MultiArray",
    TIP_POSE: "geometry_msgs/msg/PoseStamped",
    BACKBONE: "geometry_msgs/msg/PoseArray",
    BEND_CMD: "geometry_msgs/msg/Vector3Stamped",
    TIP_TARGET: "geometry_msgs/msg/PointStamped",
    TIP_MEASURED: "geometry_msgs/msg/PoseStamped",
    TIP_TRUE: "geometry_msgs/msg/PoseStamped",
    BENCH_ANGLE: "std_msgs/msg/Float64",
    BENCH_FORCE: "std_msgs/msg/Float64",
    BENCH_BEND_ANGLE: "geometry_msgs/msg/Vector3Stamped",
    BENCH_WRENCH: "geometry_msgs/msg/WrenchStamped",
    BENCH_STEP: "std_msgs/msg/String",
    BENCH_RIG: "std_msgs/msg/String",
    BENCH_TARE: "std_msgs/msg/Empty",
    BODY_MARKER: "visualization_msgs/msg/Marker",
    BACKBONE_PATH: "nav_msgs/msg/Path",
    RADIUS_L_OVER_THETA: "std_msgs/msg/Float64",
    DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray",
    READY: "std_msgs/msg/String",
}

FLUID_PRESSURE_TYPE = "sensor_msgs/msg/FluidPressure"


def pressure_measured_topic(channel: int) -> str:
    """The stamped measured-pressure topic of ``channel`` (0-based)."""
    return PRESSURE_MEASURED_CHANNEL.format(channel=int(channel))


def message_type(topic: str) -> str | None:
    """The contract's message type of ``topic`` (per-channel pressure topics included), or None."""
    if topic.startswith(PRESSURE_MEASURED + "/ch") and topic[len(PRESSURE_MEASURED) + 3:].isdigit():
        return FLUID_PRESSURE_TYPE
    return MESSAGE_TYPES.get(topic)


# The reading each bench kind (bench.protocol.BENCHES) adds to the contract, stamped and deprecated.
BENCH_READINGS = {"angle": BENCH_BEND_ANGLE, "force": BENCH_WRENCH}
DEPRECATED_BENCH_READINGS = {"angle": BENCH_ANGLE, "force": BENCH_FORCE}


def rig_topics(n_channels: int, benches=tuple(BENCH_READINGS)) -> list[str]:
    """What a rig publishes under the contract: one pressure topic per channel and the reading of
    each bench in ``benches`` (default both: angle, scale)."""
    return [pressure_measured_topic(c) for c in range(n_channels)] + [BENCH_READINGS[b] for b in benches]


def deprecated_rig_topics(benches=tuple(BENCH_READINGS)) -> list[str]:
    """The deprecated unstamped rig topics a run on ``benches`` needs."""
    return [PRESSURE_MEASURED] + [DEPRECATED_BENCH_READINGS[b] for b in benches]


# Published for one release beside the stamped topics, then removed (docs/rig.md "Deprecated").
DEPRECATED_RIG_TOPICS = deprecated_rig_topics()

# What bench_node records by default: every signal of a bench run (plus rig_topics(n) of the design).
RECORDED = [PRESSURE_CMD, BEND_CMD, PRESSURE_MEASURED, BENCH_ANGLE, BENCH_FORCE, BENCH_BEND_ANGLE, BENCH_WRENCH,
            BENCH_STEP, BENCH_RIG, TIP_POSE, BACKBONE, BODY_MARKER, BACKBONE_PATH, RADIUS_L_OVER_THETA, TIP_MEASURED,
            DIAGNOSTICS]

# Node names (the executables share the module names: model_node, ...).
MODEL_NODE = "softcath_model"
ALLOCATION_NODE = "softcath_allocation"
BENCH_NODE = "softcath_bench"
SIM_BENCH_NODE = "softcath_sim_bench"
STEER_NODE = "softcath_steer"
STEER_DRIVER = "softcath_steer_driver"
TRACKER_NODE = "softcath_tracker"
REGULATOR_NODE = "softcath_regulator"
SCALE_NODE = "softcath_scale"
# What steer-sim records.
STEERING_RECORDED = [TIP_TARGET, TIP_MEASURED, TIP_TRUE, PRESSURE_CMD, PRESSURE_MEASURED, DIAGNOSTICS]

FRAME_ID = "softcath_base"
SCALE_FRAME_ID = "softcath_scale"   # the scale under the tip: z is its measuring axis
