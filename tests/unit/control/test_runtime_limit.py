"""A controller limit changed while the loop runs (controller_node's ``command_limit``) reaches
every law at the next sample, not only the final clip: after :meth:`Controller.set_limit` the
MPC and the anti-windup LQG command what a controller built from the start with that limit
commands, from the same previous command and (MPC) the same warm start on, given the same
estimates."""

from __future__ import annotations

import numpy as np
import pytest

from stillframe.config.scene import load_scene
from stillframe.contract.signals import Estimate
from stillframe.control.factory import make_controller
from stillframe.locations import SCENES_DIR
from stillframe.loop.wiring import design_model

THESIS = SCENES_DIR / "thesis_lqg.yaml"
#: the torque-limited lumped rig of docs/controllers.md, with a slew limit (0.31 N m a sample)
RIG = ["plant.model=scene", "model.type=lumped", "design.model=lumped",
       "actuators.torque_limit=2", "actuators.torque_rate_limit=10"]
WIDE, NARROW = 1.5, 0.2


def _controller(law: str, limit: float):
    scene = load_scene(THESIS, [*RIG, *law.split(), f"controller.limit={limit}"])
    return make_controller(scene, design_model(scene)), design_model(scene)


def _estimates(design, count: int) -> list[Estimate]:
    """Estimates that call for commands well beyond the narrow limit."""
    rng = np.random.default_rng(7)
    out = []
    for k in range(count):
        z = 2e-2 * rng.standard_normal(design.n_dof * 2)
        z[design.phi_index] = 0.02 * np.sin(k)
        out.append(Estimate(30 + k / 32, z, z))       # control on from 25 s
    return out


@pytest.mark.parametrize(("law", "tolerance"), [
    # OSQP stops at eps_abs = eps_rel = 1e-3 (stillframe.control.mpc.SETTINGS): two solvers
    # with the same problem agree to that, relative to the commands' scale (the limit)
    ("controller.type=mpc", 1e-3 * NARROW),
    ("controller.type=lqg controller.anti_windup=true", 0.0),   # a closed form: exact
])
def test_a_limit_set_at_run_time_acts_as_one_built_in(law: str, tolerance: float) -> None:
    changed, design = _controller(law, WIDE)
    estimates = _estimates(design, 12)
    before = [changed.command(e.t, e, 0.0).torque for e in estimates[:6]]
    assert max(abs(u) for u in before) > NARROW          # the wide limit let them through
    changed.set_limit(NARROW)
    built, _ = _controller(law, NARROW)
    built.law.previous = changed.law.previous            # the same history ...
    if hasattr(built.law, "last"):
        built.law.last = changed.law.last                # ... and warm start
    for e in estimates[6:]:
        got, want = changed.command(e.t, e, 0.0), built.command(e.t, e, 0.0)
        assert abs(got.torque) <= NARROW + 1e-12
        assert got.torque == pytest.approx(want.torque, abs=tolerance)
    assert changed.limit == NARROW and changed.limits.magnitude == NARROW
