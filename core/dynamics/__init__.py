"""The dynamic regressor of a mechanism, its observation matrix over trajectories and
random states, model effects, and multipole transfers as null directions of W."""
