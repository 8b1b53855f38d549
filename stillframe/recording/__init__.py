"""Recording and playback over the node API: topics into a bag, and a bag back onto topics."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["player", "recorder"],
    submod_attrs={
        "recorder": ["Recorder"],
        "player": ["Player"],
    },
)
