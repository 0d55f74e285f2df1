"""Two tiny services that exercise the bus: talker (a clock source) and listener (a stateful echo)."""
