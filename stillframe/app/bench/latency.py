"""Sensor-stamp-to-command latency of the running loop, seen from one outside observer.

The observer subscribes to a sensor topic and to the command topics. A command carries the stamp
of the sample it was computed from (docs/architecture.md, topic contract), so for each stamp t_k
the latency is (time of the command stamped t_k) − (time of the sample stamped t_k). The times are
the source timestamps DDS carries with each sample (when its writer wrote it, on the host's wall
clock): the hop to the estimator, the estimator's and controller's work and the hop between
them, without the observer's own wake-ups, which a loaded machine delays by more than the loop
takes. A command later than one sample period after its sample missed its deadline (the next
sample is already due); a sample never answered is counted separately, except the samples that
came after the last command seen (still in flight when the run ended), and the samples before
the first command seen, counted as ``unobserved``: until a command reaches the observer, its
reader may not be matched with the controller's writer yet (on Fast DDS the match can come
seconds after the loop started, and every sample until then would look unanswered). sim_node's
own count of late commands covers that time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class LatencyLog:
    """Source (or receive) times (ns, wall clock) by stamp (ns) of samples and commands."""

    period_ns: int
    samples: dict[int, int] = field(default_factory=dict)
    commands: dict[int, int] = field(default_factory=dict)

    def on_sample(self, stamp_ns: int, at_ns: int) -> None:
        """Record when (``at_ns``, monotonic) the sample stamped ``stamp_ns`` was first seen."""
        self.samples.setdefault(stamp_ns, at_ns)

    def on_command(self, stamp_ns: int, at_ns: int) -> None:
        """The first command for a stamp counts (EUK and LQG answer on one topic each)."""
        self.commands.setdefault(stamp_ns, at_ns)

    def latencies_us(self) -> dict[int, float]:
        """The latency [µs] of every answered sample, by its stamp."""
        return {s: (self.commands[s] - at) * 1e-3 for s, at in self.samples.items()
                if s in self.commands}

    def summary(self) -> dict[str, float | int]:
        """p50 / p99 / max latency in µs over the answered samples, deadline misses (latency
        above one period), unanswered samples, samples before the first command (``unobserved``)."""
        answered = sorted(set(self.samples) & set(self.commands))
        latency_us = np.array([(self.commands[s] - self.samples[s]) * 1e-3 for s in answered])
        first, last = min(self.commands, default=0), max(self.commands, default=-1)
        unanswered = sum(1 for s in self.samples
                         if s not in self.commands and first <= s <= last)
        unobserved = sum(1 for s in self.samples if s < first)
        if latency_us.size == 0:
            return {"samples": len(self.samples), "answered": 0, "unanswered": unanswered,
                    "unobserved": unobserved,
                    "p50_us": float("nan"), "p99_us": float("nan"), "max_us": float("nan"),
                    "deadline_misses": 0}
        return {
            "samples": len(self.samples),
            "answered": len(answered),
            "unanswered": unanswered,
            "unobserved": unobserved,
            "p50_us": float(np.percentile(latency_us, 50)),
            "p99_us": float(np.percentile(latency_us, 99)),
            "max_us": float(latency_us.max()),
            "deadline_misses": int(np.sum(latency_us > self.period_ns * 1e-3)),
        }
