"""The application: the ``stillframe`` command, its subcommands and the process launcher."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["cli", "commands", "experiment", "experiment_report", "experiment_test_force",
                "fault_bench", "graph_daemon", "launcher", "net_faults", "netns_lab",
                "nfqueue_delay", "ros_tools", "run_verdict", "running_graph", "tracking"],
    submod_attrs={
        "cli": ["main"],
        "launcher": ["run_scene"],
    },
)
