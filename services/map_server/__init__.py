"""Map server: loads, saves and serves maps in the ROS map_server format."""
