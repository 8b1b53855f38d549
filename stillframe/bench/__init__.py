"""Benchmark kernels and instruments that are not a command's own code: the transport
ping-pong, the profile of a sample's hops, latency and estimate-error logs, memory and stall
probes."""
