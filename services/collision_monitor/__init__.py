"""collision_monitor: the last check on a command before the chassis (Nav2's collision_monitor), on the raw scan and the tracks."""
