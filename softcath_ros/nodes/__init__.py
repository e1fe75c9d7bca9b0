"""ROS 2 adapters: thin rclpy nodes that parse messages, call the core and publish.

No physics here (docs/architecture.md). Shared plumbing for every node: ``runtime``
(executors, clean shutdown), ``qos`` (profiles from parameters) and
``diagnostics`` (input counters reported on /diagnostics).
"""
