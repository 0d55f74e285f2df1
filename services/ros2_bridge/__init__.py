"""The ROS 2 bridge: omninav's keys to and from a ROS 2 robot that runs rmw_zenoh, without ROS."""
