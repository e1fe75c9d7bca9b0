"""Small ROS clients for scripts, demos and benchmarks (not nodes of the suite)."""
