"""rosbag2 bags: storage, QoS metadata, recording, playback and recovery."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["channels", "checked_mcap", "full_disk", "lone_mcap", "metadata", "qos", "reindex",
                "storage"],
    submod_attrs={
        "storage": ["BagWriter", "bag_summary", "open_bag", "read_bag"],
        "channels": ["Channel", "read_record"],
    },
)
