"""The mechanism model: bodies, joints with their frames, coordinates, geometry held as
exact expressions, the inertial parameter names. Pure data: nothing here computes."""
