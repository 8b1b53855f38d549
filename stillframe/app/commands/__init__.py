"""Subcommands of the ``stillframe`` command; each module has ``register(subparsers)``."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["adapt", "bag", "bench", "closed_loop", "daemon", "demo", "experiment", "identify",
                "identify_daisy", "interface", "launch", "lifecycle", "modes", "monitor",
                "montecarlo", "netns", "node", "param", "ph", "play", "record", "reproduce",
                "simulate", "topic"],
)
