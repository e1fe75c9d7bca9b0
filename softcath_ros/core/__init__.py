"""Pure core: designs, materials, the model ladder and kinematics. Never imports rclpy."""
