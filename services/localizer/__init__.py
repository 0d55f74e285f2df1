"""AMCL localization on a known map: the pure core (params, motion, sensor, filter) and its bench."""
