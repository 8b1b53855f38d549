"""Energy drift rows of bench fidelity: the pHDAE integrator conserves H where RK4 and the
midpoint rule on the other models drift."""

from stillframe.dynamics.ph.energy_drift import energy_drift_rows


def test_ph_rows_conserve_energy_and_follow_the_fe40_reference():
    rows = {(r.model, r.method): r for r in energy_drift_rows(duration=0.2, dt=2e-3)}
    ph = rows[("ph2", "avf-midpoint")]
    assert ph.energy_drift < 1e-12
    for key in (("lumped", "rk4"), ("lumped", "midpoint"), ("fe3", "midpoint")):
        assert rows[key].energy_drift > 100 * ph.energy_drift, key
    assert ph.error_vs_fe40 < 1e-3
    assert rows[("fe3", "rk4")].energy_drift is None  # 2 ms is beyond its stability limit
