"""Recording the bus to MCAP, and recovering files whose writer was killed."""
