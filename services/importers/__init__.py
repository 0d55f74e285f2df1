"""Converters from other robots' log formats into omninav messages (CARMEN logs, ...)."""
