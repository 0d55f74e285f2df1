"""The costmap service core: layered costmaps (static, obstacle, inflation, keepout) after ROS costmap_2d."""
