"""stillframe: simulate, identify and control a flexible frame with a pendulum damper."""

import lazy_loader as lazy

__version__ = "0.1.0"

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["app", "bags", "config", "contract", "control", "design", "durations", "dynamics",
                "errors", "estimation", "fidelity", "files", "identification", "interrupts",
                "locations", "loop", "middleware", "monitor", "node_runtime", "plant",
                "recording", "studies", "text_table"],
)
