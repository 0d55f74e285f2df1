"""velocity_smoother: the command chain's ramp (Nav2's velocity_smoother) between the command mux and the collision monitor."""
