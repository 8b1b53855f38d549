"""Everything a node would refuse in a scene is refused by ``stillframe launch`` before it starts
any process: one line, exit code 2, no child started (the launcher says ``started NAME`` for
each child it starts). The launch builds what each node builds, with the nodes' own functions
(:func:`stillframe.loop.parts.check_loop`), so the line is the node's."""

from __future__ import annotations

import pytest

from tests.support.middleware import run_stillframe

#: (scene, overrides, the start of the one line): each passes the scene's key checks, and a
#: node refuses it when it builds its part
REFUSED = [
    ("hammer_test", ["integrator.dt=0.003"],
     "integrator.dt: 0.003 s does not divide the sample period"),
    ("thesis_lqg", ["plant.file=/nonexistent.yaml"], "plant.file: '/nonexistent.yaml' is neither"),
    ("thesis_lqg", ["design.file=/nonexistent.yaml"],
     "design.file: '/nonexistent.yaml' is neither"),
    ("thesis_lqg", ["plant.model=scene", "plant.discretization=zoh"],
     "plant.discretization: zoh needs the linear plant"),
    ("thesis_lqg", ["controller.type=passivity", "controller.injection_damping=100"],
     "controller.injection_damping: k_d T / J ="),
    ("ph_passivity", ["integrator.dt=0.03125", "plant.process_noise_std=[1e-3,0,0,0,0,0,0,0]"],
     "plant.process_noise_std: model.type ph takes displacement noise as a force doublet"),
    ("change_mass_floor2", ["events=[{time: 5, damping: {alpha: -5}}]"],
     "events[0]: the structure after it: damping.beta: Rayleigh damping (alpha=-5"),
]


@pytest.mark.parametrize(("scene", "overrides", "line"), REFUSED,
                         ids=[" ".join(o) for _, o, _ in REFUSED])
def test_a_scene_a_node_refuses_is_refused_before_any_process(
        ros_domain: int, scene: str, overrides: list[str], line: str) -> None:
    done = run_stillframe("launch", scene, *(f"--set={o}" for o in overrides), timeout=120)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"stillframe launch: error: {line}"), lines
    assert "started" not in done.stderr and "Traceback" not in done.stderr
