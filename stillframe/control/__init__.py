"""Control laws for the loop: LQG, extended Udwadia–Kalaba and passivity-based control behind a
supervisor (what controller_node runs)."""
