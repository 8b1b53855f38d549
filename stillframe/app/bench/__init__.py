"""The benchmarks, in one home: each ``stillframe bench NAME`` (a module of :data:`BENCHES`, with
``register(subparsers)`` and ``run(args)`` like a command), the runs several share
(:mod:`.fault_runs`) and the instruments only benchmarks use (the transport ping-pong
:mod:`.pingpong`, the profile of a sample's hops :mod:`.hop_profile`, the phases of every sample
:mod:`.phases`, latency and estimate-error logs, memory :mod:`.rss` and stall probes, busy loops,
a settled machine). Each prints its figures as ratios against a baseline measured in the same
run.
"""

import lazy_loader as lazy

#: the benchmarks ``stillframe bench`` lists, in the order it lists them
BENCHES: tuple[str, ...] = tuple(f"stillframe.app.bench.{name}" for name in (
    "transport", "identify", "identify_hammer", "loop", "scaling", "hops", "monitor",
    "fidelity", "speed", "montecarlo", "faults", "soak", "cli", "controllers", "writers"))

__getattr__, _dir_of_modules, _modules = lazy.attach(
    __name__,
    submodules=["busy", "cli", "controllers", "estimate_error", "fault_runs", "faults",
                "fidelity", "hop_profile", "hops", "identify", "identify_hammer", "latency",
                "loop", "monitor", "montecarlo", "phases", "pingpong", "recorder_load", "rss",
                "scaling", "settle", "soak", "speed", "stall_probe", "transport", "writers"],
)
__all__ = sorted(["BENCHES", *_modules])


def __dir__() -> list[str]:
    """The names of :data:`__all__`: :data:`BENCHES`, defined here, and the modules, imported on
    first use."""
    return list(__all__)
