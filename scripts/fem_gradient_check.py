"""The FEM grasp's L_opt gradient against central differences, on linear or quadratic tets.

The case of ``tests/test_fem_grasp.py::test_l_opt_gradient_matches_central_differences`` (a 20 ms grasp
of a 100 kg/m³ box that starts in contact, paper-optimized design, 2 N, 10 µs, contact damping off, the
coarse mesh), run here for a mesh the test does not cover in CI (``--order 2``: about 90 s on one core).
Prints one JSON line: the adjoint and the central difference (ln E step 1e-5) for the steepest block of
each finger and blocks 3 and 14, with their relative differences.

    python3 scripts/fem_gradient_check.py --order 2
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np


def main() -> None:
    """Run the check for the chosen mesh and print the JSON line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--order", type=int, choices=(1, 2), default=2, help="tet order")
    p.add_argument("--locking-correction", action="store_true", help="linear tets only")
    args = p.parse_args()
    import warp as wp

    wp.config.quiet = True  # stdout is the JSON line
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models.types import FingerModel
    from mjcodesign.objects import box_object
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, auto_pose, build_scene
    from mjcodesign.sim.fem import FemDynamics, FemOptions, fem_grasp_loss_and_grad
    from mjcodesign.sim.fem.grasp_outcome import paper_loss
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp

    t0 = time.perf_counter()
    obj = box_object((0.04, 0.04, 0.06), 100.0)
    design = FingerDesign()
    scene = build_scene(
        obj, design, Stiffness.preset("paper-optimized"), FingerModel.CHAIN, auto_pose(obj, design)
    )
    scene = dataclasses.replace(scene, start_openings=(0.0152, 0.0152))  # touching the box's top edge
    phases = dict(settle_s=0.0, close_s=0.002, tighten_s=0.004, lift_s=0.004, hold_s=0.008, post_hold_s=0.002)
    scenario = GraspScenario(**phases, tendon=TendonForce(tension=2.0), lift=0.002, impulse=0.0)
    dyn = FemDynamics(
        dt=1e-5, contact_kd=0.0
    )  # kd's onset jump is invisible to the adjoint (the test's note)
    mesh = FemOptions(
        h=10e-3, h_flexure=8e-3, spine_layers=2, waypoint_layers=False,
        order=args.order, locking_correction=args.locking_correction,
    )  # fmt: skip
    grasp = FemGrasp(scene, scenario, options=mesh, dynamics=dyn)
    loss, grad, _, _ = fem_grasp_loss_and_grad(
        scene.built.stiffness, scene.obj, scene.pose, scenario=scenario, options=mesh, dynamics=dyn,
        start_openings=scene.start_openings, segment=300, gripper=grasp.gripper,
    )  # fmt: skip
    t_grad = time.perf_counter() - t0
    le0 = scene.built.stiffness.log_e.ravel().copy()

    def loss_at(le):
        grasp.gripper.set_log_e(le, rescale_mass=False)  # the adjoint holds the masses fixed too
        r = grasp.run()
        return paper_loss(r.outcome.body_force, r.outcome.displacement, r.ground_points)[0]

    replay = loss_at(le0)
    h = 1e-5
    rows = []
    for i in (int(np.argmax(np.abs(grad[:11]))), int(np.argmax(np.abs(grad[11:]))) + 11, 3, 14):
        e = np.zeros(22)
        e[i] = 1.0
        fd = (loss_at(le0 + h * e) - loss_at(le0 - h * e)) / (2 * h)
        rows.append(
            {"block": i, "adjoint": float(grad[i]), "central": fd, "rel_diff": abs(grad[i] - fd) / abs(fd)}
        )
    out = {
        "order": args.order,
        "locking_correction": args.locking_correction,
        "loss": loss,
        "replay_equal": replay == loss,
        "added_mass_fraction": grasp.gripper.added_mass_fraction,
        "gradient_s": round(t_grad, 1),
        "total_s": round(time.perf_counter() - t0, 1),
        "blocks": rows,
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
