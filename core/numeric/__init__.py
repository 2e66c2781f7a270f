"""Arithmetics behind one interface (float64, python-flint balls, exact rationals, sympy),
so kinematics and dynamics are written once; certified rank analysis of ball matrices."""
