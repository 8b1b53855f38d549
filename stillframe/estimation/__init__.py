"""State estimation for the loop: Kalman filters, the EKF and the exact-state pass-through
(what estimator_node runs)."""
