"""Benchmark kernels and instruments that are not a command's own code: the transport
ping-pong, the profile of a sample's hops, latency and estimate-error logs, memory and stall
probes."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["busy", "estimate_error", "hops", "latency", "phases", "pingpong", "recorder_load",
                "settle", "soak", "stall_probe"],
)
