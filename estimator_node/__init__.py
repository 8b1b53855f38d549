"""State estimation for the loop: steady-state and time-varying Kalman filters on a linear model,
an EKF on the nonlinear model, and the exact-state pass-through (DESIGN.md, estimator_node).

Plain numpy; the node wraps :func:`estimator_node.factory.make_estimator`'s ``step``.
"""
