"""``genbacklash demo --live``: a simulated arm and the identifier node in one ROS 2 graph."""
