"""Decimated taps: the simulator's sample topics anti-alias filtered and thinned at the writer,
on hidden twin topics, for readers that want the structure's band but not every sample (the
modal tracker).

Every reader of a topic costs its writer one send per sample (:mod:`stillframe.middleware.taps`),
and a reader that takes every sample of a 1 kHz loop pays for 4000 messages a second to identify
modes below 10 Hz. So at sensor rates of :data:`MIN_RATE_HZ` × 2 and above the simulator also
publishes each sample topic's twin ``/_decimated<topic>`` (a token starting with ``_``: hidden,
like the monitor's taps) at ``rate_hz / q``, q = ⌊rate_hz / MIN_RATE_HZ⌋ (1 kHz: q = 20, 50 Hz).

Decimating by keeping every q-th sample would fold everything between the new Nyquist frequency
and the old one onto the structure's band. The taps therefore carry the output of a linear-phase
FIR low-pass (:class:`Decimator`; a Kaiser window for :data:`STOPBAND_DB` of attenuation from
:func:`scipy.signal.kaiserord`, designed by :func:`scipy.signal.firwin`): flat to 0.3 of the
tap's rate, attenuated by :data:`STOPBAND_DB` from its Nyquist frequency (0.5 of its rate) up,
so what folds onto the tap's band is that far down. It is the same filter on every channel, so
the input-output relation an identification reads is kept; its delay of (L - 1) / 2 input
samples is taken out of the stamps: each tapped sample is stamped with the time of the sample
at the filter's centre, a multiple of q sample periods from the start, so the taps of all topics
share one grid. Only what scipy cannot do as a stream is written here: the ring of the last L
samples and the dot product every q-th sample.

The QoS is the topic's own (best effort in real time: a slow reader never makes the simulator
wait; reliable in lock-step, where every sample counts). Below ``2 × MIN_RATE_HZ`` there is no
tap (:func:`decimation_factor` is 1): the topic itself is read.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from stillframe.contract.codecs import SAMPLE_TOPICS, SensorMessages
from stillframe.contract.signals import Sample
from stillframe.contract.topics import TopicSpec
from stillframe.middleware.names import resolve_topic

PREFIX = "/_decimated"
#: the lowest rate a tap carries [Hz]: the frame's modes lie below 10 Hz, inside its flat band
MIN_RATE_HZ = 50.0
#: attenuation from the tap's Nyquist frequency up [dB]
STOPBAND_DB = 60.0
#: the pass band's edge and the stop band's, as fractions of the tap's rate
PASS_EDGE, STOP_EDGE = 0.3, 0.5


def decimated_topic(topic: str) -> str:
    """The hidden twin of the absolute ``topic`` that carries its decimated samples."""
    return PREFIX + topic


def undecimated(topic: str) -> str:
    """``topic`` without the twin's prefix (the topic the twin thins)."""
    return topic[len(PREFIX):] if topic.startswith(PREFIX + "/") else topic


def decimation_factor(rate_hz: float) -> int:
    """q for a sensor rate: ⌊rate_hz / MIN_RATE_HZ⌋, at least 1 (1: no tap)."""
    return max(1, math.floor(rate_hz / MIN_RATE_HZ + 1e-9))


def anti_alias_taps(factor: int) -> np.ndarray:
    """The FIR's coefficients for decimation by ``factor``: odd length L with (L - 1) / 2 a
    multiple of ``factor`` (the centre falls on the decimated grid), unit gain at DC."""
    # imported here: scipy.signal takes longer to import than the rest of a node, and a
    # simulator below MIN_RATE_HZ never designs a filter
    from scipy import signal

    nyquist_out = 1.0 / factor                     # in units of the input's Nyquist frequency
    width = (STOP_EDGE - PASS_EDGE) * 2 * nyquist_out
    numtaps, beta = signal.kaiserord(STOPBAND_DB, width)
    half = factor * math.ceil((numtaps - 1) / 2 / factor)
    cutoff = (STOP_EDGE + PASS_EDGE) * nyquist_out
    return signal.firwin(2 * half + 1, cutoff, window=("kaiser", beta))


class Decimator:
    """Streaming anti-alias filter and decimation by ``factor`` of ``channels`` signals: each
    :meth:`push` takes one sample; every ``factor``-th returns the filtered value at the
    filter's centre and that sample's stamp (module docstring)."""

    def __init__(self, factor: int, channels: int) -> None:
        self.factor = factor
        self.taps = anti_alias_taps(factor)
        self.length = len(self.taps)
        self.delay = (self.length - 1) // 2
        # each sample written twice, L apart: the last L are always one contiguous slice
        self._ring = np.zeros((2 * self.length, channels))
        self._stamps = np.zeros(self.length, dtype=np.int64)
        self.count = 0

    def push(self, values: Any, stamp: int) -> tuple[np.ndarray, int] | None:
        """Take one sample of every channel, stamped ``stamp``; when the filter's centre (the sample
        :attr:`delay` back) is a ``factor``-th sample, the filtered values there and its stamp, else
        None. Before the first sample the filter sees zeros."""
        i = self.count % self.length
        self._ring[i] = self._ring[i + self.length] = values
        self._stamps[i] = stamp
        self.count += 1
        centre = self.count - 1 - self.delay
        if centre < 0 or centre % self.factor:
            return None
        return (self.taps @ self._ring[i + 1: i + 1 + self.length],
                int(self._stamps[centre % self.length]))


class DecimatedTaps:
    """The decimated twins of the simulator's sample topics (:data:`SAMPLE_TOPICS`), published
    from the samples it publishes. :meth:`of` gives None when the rate needs no tap."""

    def __init__(self, node: Any, messages: SensorMessages, factor: int,
                 qos: Callable[[TopicSpec], Any]) -> None:
        ns = node.get_namespace()
        self.publishers = [node.create_publisher(s.type_name, decimated_topic(
            resolve_topic(s.name, ns)), qos(s)) for s in SAMPLE_TOPICS]
        self.messages = messages
        # measurements (accelerometers, encoder), the load cell, the applied [torque, force]
        self.decimator = Decimator(factor, 7)
        self._truth = np.zeros(8)

    @classmethod
    def of(cls, node: Any, messages: SensorMessages, rate_hz: float,
           qos: Callable[[TopicSpec], Any]) -> DecimatedTaps | None:
        """The taps of a simulator publishing at ``rate_hz``, decimated by
        :func:`decimation_factor`; None when that is 1 (the rate needs no tap)."""
        factor = decimation_factor(rate_hz)
        return cls(node, messages, factor, qos) if factor > 1 else None

    def publish(self, sample: Sample, ns: int) -> None:
        """Take ``sample`` stamped ``ns``; publish the taps when a decimated sample is due."""
        applied = (0.0, 0.0) if sample.applied is None else sample.applied
        out = self.decimator.push((*sample.measurements[:4], sample.force, *applied), ns)
        if out is None:
            return
        values, stamp = out
        filtered = Sample(stamp * 1e-9, values[:4], float(values[4]), applied=values[5:7],
                          truth=self._truth)
        for pub, cdr in zip(self.publishers, self.messages.cdr(filtered, stamp), strict=False):
            pub.publish(cdr)
