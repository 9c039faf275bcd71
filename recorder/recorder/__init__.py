"""Recording runs to MCAP in the rosbag2 conventions, replaying them, and reports from them."""
