"""The topic contract: topics, ROS 2 message types, and the codecs between the loop's signals
and the messages (one table of which field carries what)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["adaptation_events", "codecs", "fixed_cdr", "message_yaml", "messages",
                "model_file", "run_token", "signals", "structure_events", "topics"],
    submod_attrs={
        "signals": ["Command", "Estimate", "Sample"],
        "topics": ["CONTRACT", "TopicSpec"],
        "model_file": ["read_archive", "write_archive"],
    },
)
