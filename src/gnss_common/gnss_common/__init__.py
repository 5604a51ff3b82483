"""Pure-Python GNSS foundations shared by the suite's nodes (never imports rclpy)."""
