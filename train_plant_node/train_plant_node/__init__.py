"""Train plant: longitudinal train dynamics (pure-Python core) and its rclpy node."""
