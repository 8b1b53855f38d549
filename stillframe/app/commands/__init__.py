"""Subcommands of the ``stillframe`` command; each module has ``register(subparsers)``."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["bag", "bench", "bench_cli", "bench_controllers", "bench_faults", "bench_fidelity",
                "bench_hops", "bench_identify", "bench_identify_hammer", "bench_loop",
                "bench_monitor", "bench_montecarlo", "bench_scaling", "bench_soak", "bench_speed",
                "bench_transport", "bench_writers", "closed_loop", "common", "daemon", "demo",
                "experiment", "identify", "identify_daisy", "interface", "launch", "lifecycle",
                "modes", "monitor", "montecarlo", "netns", "node", "param", "ph", "play", "record",
                "reproduce", "simulate", "topic"],
)
