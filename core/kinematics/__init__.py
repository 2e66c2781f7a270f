"""Tree kinematics in any arithmetic (poses, Jacobians, bias accelerations), loop-closure
equations, and the Krawczyk enclosure of a closure solution."""
