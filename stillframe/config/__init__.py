"""Scene configuration: the declared keys with their checks, loading and overrides."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["environment", "events", "labels", "loop_sections", "scene", "schema", "yamlio"],
    submod_attrs={
        "scene": ["Scene", "load_scene", "scene_from_dict"],
        "schema": ["key", "section"],
    },
)
