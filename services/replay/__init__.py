"""Replaying recordings: live onto the bus, or deterministically into one service."""
