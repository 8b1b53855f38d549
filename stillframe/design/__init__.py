"""The design model shared by estimation and control: coordinates, discretization at the
sample period, and the discrete algebraic Riccati equation."""
