"""The identification package (ROS 2, ament_python): ``identify_bag`` (the ``stillframe identify``
command, started as ``ros2 run identification identify_bag BAG …``) and ``modal_tracker``, the
live modal tracker node. A thin shell: the algorithms are in :mod:`stillframe.identification`
(docs/identification-tool.md, "Live modal tracking")."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["identify_bag", "node"],
    submod_attrs={
        "node": ["ModalTrackerNode"],
    },
)
