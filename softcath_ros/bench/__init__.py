"""The bench (docs/actuator.md "The bench"): protocols, the simulated rig, analysis and calibration.

Pure core: no rclpy. bench_node and sim_bench_node are thin adapters around it.
"""
