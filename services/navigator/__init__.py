"""The navigator core: move_base's goal, replanning and recovery logic as a pure state machine."""
