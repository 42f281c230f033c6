"""The node's transports: rclpy (ROS 2) and plain DDS (cyclonedds)."""
