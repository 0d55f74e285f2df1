"""The neutral layer for parameters: how a parameter class declares each field's allowed values
(declare.py) and how one is built from a YAML or ROS-style mapping (from_mapping.py). Standard library
only, so every core, node, the sim and geometry's frame mixin stand on it."""
