"""Benchmark kernels that are not a command's own code (transport ping-pong)."""
