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
TIP_MEASURED = "/softcath/tip_measured"            # measured tip pose (camera / EM tracker), stamped when taken
TIP_TRUE = "/softcath/bench/tip_true"              # simulated rig only: the true tip pose, for scoring
BENCH_ANGLE = "/softcath/bench/angle"              # measured bending angle, rad
BENCH_FORCE = "/softcath/bench/force"              # measured blocking force, N
BENCH_STEP = "/softcath/bench/step"                # protocol markers (JSON)
BENCH_RIG = "/softcath/bench/rig"                  # the rig announces itself (JSON, transient local)
DIAGNOSTICS = "/diagnostics"

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
    BENCH_STEP: "std_msgs/msg/String",
    BENCH_RIG: "std_msgs/msg/String",
    DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray",
}

# What bench_node records by default: every signal of a bench run.
RECORDED = [PRESSURE_CMD, BEND_CMD, PRESSURE_MEASURED, BENCH_ANGLE, BENCH_FORCE, BENCH_STEP, BENCH_RIG,
            TIP_POSE, BACKBONE, DIAGNOSTICS]

# Node names (the executables share the module names: model_node, ...).
MODEL_NODE = "softcath_model"
ALLOCATION_NODE = "softcath_allocation"
BENCH_NODE = "softcath_bench"
SIM_BENCH_NODE = "softcath_sim_bench"
STEER_NODE = "softcath_steer"
STEER_DRIVER = "softcath_steer_driver"
# What steer-sim records.
STEERING_RECORDED = [TIP_TARGET, TIP_MEASURED, TIP_TRUE, PRESSURE_CMD, PRESSURE_MEASURED, DIAGNOSTICS]

FRAME_ID = "softcath_base"
