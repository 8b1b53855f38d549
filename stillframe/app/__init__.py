"""The application: the ``stillframe`` command, its subcommands, the arguments they share, the
benchmarks and the process launcher."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["adaptation_experiment", "adaptation_plot", "arguments", "bench", "cli",
                "commands", "experiment", "experiment_report", "experiment_test_force",
                "graph_daemon", "launch_cli", "launcher", "net_faults", "netns_lab",
                "nfqueue_delay", "ros_tools", "run_verdict", "running_graph", "thesis_targets",
                "tracking"],
    submod_attrs={
        "cli": ["main"],
        "launcher": ["run_scene"],
    },
)
