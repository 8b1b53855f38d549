"""Live monitoring: the Foxglove bridge, its client and the built-in dashboard."""
