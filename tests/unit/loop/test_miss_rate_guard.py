"""The simulator's guard against a degraded control path: zero actuation once more than the
limit of the last window's samples missed their command, until no more than half of it does."""

from __future__ import annotations

from stillframe.loop.watchdog import MissRateGuard


def test_trips_above_the_limit_and_recovers_below_half_of_it() -> None:
    guard = MissRateGuard(window=10, limit=0.25)
    # 3 misses in 10 are 30 % > 25 %: tripped at the third
    assert [guard.record(m) for m in [True, False, True, False, True]] == [
        False, False, False, False, True]
    # it stays tripped at 20 % (above half the limit) ...
    assert [guard.record(False) for _ in range(5)] == [True] * 5   # window: T F T F T F F F F F
    assert guard.misses == 3
    assert guard.record(False) is True      # F T F T F F F F F F: 20 %
    assert guard.record(False) is True      # T F T F F F F F F F: 20 %
    assert guard.record(False) is False     # F T F F F F F F F F: 10 % <= 12.5 %
    assert guard.misses == 1


def test_a_limit_of_zero_never_trips() -> None:
    guard = MissRateGuard(window=5, limit=0.0)
    assert not any(guard.record(True) for _ in range(20))
    assert guard.misses == 5
