"""The actuators' fixed delay: the command answering sample k is applied over period k + d;
one not in when its period starts is late (the held command stays), and one that comes after
that is never applied."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.plant.actuation_delay import ActuationDelay


def command(value: float) -> np.ndarray:
    return np.array([value, 0.0])


@pytest.mark.parametrize("d", [0, 1, 3])
def test_each_command_is_applied_d_periods_after_its_sample(d: int) -> None:
    delay = ActuationDelay(d)
    applied, late = [], []
    for k in range(10):
        delay.put(k, command(10.0 + k))
        value, was_late = delay.due(k)
        applied.append(value[0])
        late.append(was_late)
    assert applied == [0.0] * d + [10.0 + k for k in range(10 - d)]
    assert late == [False] * 10


def test_arrival_order_does_not_matter_within_the_delay() -> None:
    """Commands for samples 1 and 2 come in the opposite order, both before period 3."""
    delay = ActuationDelay(2)
    delay.put(0, command(1.0))
    assert delay.due(0)[0][0] == 0.0 and delay.due(1)[0][0] == 0.0
    delay.put(2, command(3.0))
    assert delay.due(2)[0][0] == 1.0
    delay.put(1, command(2.0))
    assert [delay.due(k)[0][0] for k in (3, 4)] == [2.0, 3.0]


def test_a_late_command_holds_the_last_and_is_never_applied_after() -> None:
    delay = ActuationDelay(1)
    delay.put(0, command(1.0))
    assert delay.due(1)[0][0] == 1.0
    value, late = delay.due(2)          # the command for sample 1 is not here
    assert (value[0], late) == (1.0, True)
    delay.put(1, command(2.0))          # too late: its period has begun
    delay.put(2, command(3.0))
    value, late = delay.due(3)
    assert (value[0], late) == (3.0, False)
    value, late = delay.due(4)
    assert (value[0], late) == (3.0, True)


@pytest.mark.parametrize("d", [0, 1, 3])
def test_commands_that_can_no_longer_be_due_are_not_kept(d: int) -> None:
    """A caller that never asks what is due (sim_node with d = 0 applies the newest command
    itself) keeps at most d + 1 commands, not one per sample: the one-hour soak found the
    simulator growing by 27 MiB that way. What is due is unchanged (the reordered put of
    sample k − d still waits)."""
    delay = ActuationDelay(d)
    for k in range(10_000):
        delay.put(k, command(float(k)))
    assert len(delay) == d + 1
    delay.put(10_000 - 1 - d, command(-1.0))       # a later command for the oldest waiting
    assert delay.due(10_000 - 1)[0][0] == -1.0
