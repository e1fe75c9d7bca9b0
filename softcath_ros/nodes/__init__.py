"""ROS 2 adapters: thin rclpy nodes around the core (architecture.md "Nodes")."""
