"""ATO controller: selectable control laws (pure-Python core) and the rclpy node that runs them."""
