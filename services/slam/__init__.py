"""SLAM: a Rao-Blackwellized particle filter of the gmapping class over log-odds occupancy grids."""
