"""Identification and diagnosis: measured data, simulation, least squares, the missing-effect loop."""
