"""Probe of the soft finger's collapse in the Warp FEM grasp (documentation: validation, the FEM grasp study).

One case of the grasp study (`mjcodesign.crosscheck.grasp`: the sampler's pose, the light object) in the
chain and in the study's FEM (10 mm cells, 8 mm in the flexures, 2 spine layers, locking-corrected linear
tets, or quadratic ones; 4 µs, contact ke 1e7 at ζ = 1), with one setting changed at a time: the tension,
the ramp, the mass damping, the friction, gravity, the tendon's height, or the palm raised out of reach
(``--free-space``: the fingers close on air). Prints one JSON line: both outcomes and, with
``--angles``, finger A's flexure angles in the FEM (relative rotation of the segments on either side
about the finger's width axis, inward positive: inward closes the gap) and in the chain (its flexure
hinges) at the given times.

    python3 scripts/fem_soft_collapse.py --design soft --free-space --angles 0.166,0.198,0.230

Runs 20-120 s on one core (the FEM stops at its first inverted tet). Not part of the package: a record of
how the numbers of the FEM grasp study were made (record: ``benchmarks/records/*_fem_soft_collapse.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np


def _parse() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--object", default="box")
    p.add_argument("--pose", type=int, default=0)
    p.add_argument("--design", default="soft", help="preset, random:SEED or 11/22 comma-separated ln E")
    p.add_argument("--tension", type=float, default=4.0, help="[N]")
    p.add_argument("--tighten-s", type=float, default=None, help="length of the tension ramp [s]")
    p.add_argument("--mass-damping", type=float, default=None, help="FEM mass damping [1/s]")
    p.add_argument(
        "--friction", type=float, default=None, help="FEM Coulomb coefficient (the chain keeps its own)"
    )
    p.add_argument("--gravity", type=float, default=9.81, help="[m/s²], FEM only")
    p.add_argument("--free-space", action="store_true", help="raise the palm 150 mm: nothing to grasp")
    p.add_argument("--order", type=int, choices=(1, 2), default=1, help="FEM tets (1: locking-corrected)")
    p.add_argument("--locked", action="store_true", help="linear tets without the locking correction")
    p.add_argument("--tendon-offset", type=float, default=0.0, help="raise every waypoint [m] (both)")
    p.add_argument(
        "--no-flexure-guides", action="store_true", help="FEM: the tendon straight across every gap (printed)"
    )
    p.add_argument(
        "--tendon-law", choices=("frictionless", "paper"), default="frictionless", help="FEM tendon"
    )
    p.add_argument("--angles", default="", help="comma-separated times [s] for the flexure angles")
    return p.parse_args()


def _patch_tendon(offset: float) -> None:
    from mjcodesign.design import finger

    if offset == 0.0:
        return
    plain = finger.FingerDesign.waypoints

    def raised(self):
        w = plain(self).copy()
        w[:, 2] += offset
        return w

    finger.FingerDesign.waypoints = raised


def _segment_rotation(rest: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Best-fit rotation R with now ≈ R rest + c (Kabsch)."""
    a, b = rest - rest.mean(0), now - now.mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    return (u @ d @ vt).T


def fem_flexure_angles(gripper, x: np.ndarray) -> list[float]:
    """Finger A's flexure angles [rad], inward positive, from its vertices ``x`` (world)."""
    n = gripper.n_per_finger
    mesh = gripper.fingers[0].mesh
    rest, tets = mesh.vertices, mesh.tets
    block = gripper.tet_block_np[: len(tets)]
    xa = x[:n]
    base = np.flatnonzero(np.asarray(gripper.pinned[:n]).astype(bool))
    frame = _segment_rotation(rest[base], xa[base])  # the finger frame in the world (its base is clamped)
    rot = {}
    for b in range(0, gripper.n_blocks, 2):
        v = np.unique(tets[block == b])
        rot[b] = frame.T @ _segment_rotation(rest[v], xa[v])
    out = []
    for b in range(2, gripper.n_blocks, 2):
        r = rot[b - 2].T @ rot[b]
        angle = np.arctan2(r[0, 2] - r[2, 0], r[0, 0] + r[2, 2])  # about the finger's y (width) axis
        out.append(round(float(-angle), 3))  # a rotation about +y turns the tip down: outward
    return out


def main() -> None:
    """Run the case in both simulators with the flags and print the JSON line."""
    args = _parse()
    _patch_tendon(args.tendon_offset)
    import warp as wp

    wp.config.quiet = True  # stdout is the JSON line
    import mujoco

    from mjcodesign.crosscheck.grasp import _Keep, _load
    from mjcodesign.design.finger import FingerDesign
    from mjcodesign.design.stiffness import Stiffness
    from mjcodesign.models.types import FingerModel
    from mjcodesign.poses import sample_poses, to_gripper_pose
    from mjcodesign.scenarios.drive import TendonForce
    from mjcodesign.scenarios.grasp import GraspScenario, build_scene
    from mjcodesign.sim.fem import FemDynamics, FemOptions
    from mjcodesign.sim.fem.gripper_grasp import FemGrasp
    from mjcodesign.sim.mujoco_c import MujocoBackend

    design = FingerDesign()
    obj = _load(args.object, "light", None)
    pose = to_gripper_pose(sample_poses(obj, 2, seed=0, design=design), args.pose)
    if args.free_space:
        pose = dataclasses.replace(pose, position=tuple(np.asarray(pose.position) + [0.0, 0.0, 0.15]))
    scene = build_scene(obj, design, Stiffness.parse(args.design), FingerModel.CHAIN, pose)
    kw = {"tendon": TendonForce(tension=args.tension)}
    if args.tighten_s is not None:
        kw["tighten_s"] = args.tighten_s
    scenario = GraspScenario(**kw)
    dyn = {"dt": 4e-6, "contact_ke": 1e7, "contact_damping_ratio": 1.0, "gravity": (0.0, 0.0, -args.gravity)}
    if args.mass_damping is not None:
        dyn["mass_damping"] = args.mass_damping
    if args.friction is not None:
        dyn["friction"] = args.friction
    dynamics = FemDynamics(**dyn)
    options = FemOptions(
        h=10e-3, h_flexure=8e-3, spine_layers=2, waypoint_layers=False,
        locking_correction=args.order == 1 and not args.locked, order=args.order,
        flexure_guides=not args.no_flexure_guides, tendon_law=args.tendon_law,
    )  # fmt: skip
    times = [float(t) for t in args.angles.split(",")] if args.angles else []

    keep = _Keep()  # the chain's states, for its hinge angles
    chain = MujocoBackend(nthread=1).run(scene, scenario, observer=keep)
    m = keep.kept.model
    d = mujoco.MjData(m)
    flex = [m.joint(f"A_hinge{i}").qposadr[0] for i in range(1, 11, 2)]
    chain_angles = {}
    for t in times:
        k = min(int(round(t / m.opt.timestep)) - 1, len(keep.kept.states) - 1)
        mujoco.mj_setState(m, d, keep.kept.states[k], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        chain_angles[f"{t:.3f}"] = [round(float(d.qpos[a]), 3) for a in flex]

    t0 = time.perf_counter()
    grasp = FemGrasp(scene, scenario, options=options, dynamics=dynamics)
    checkpoints = {int(round(t / dynamics.dt)): t for t in times}
    run = grasp.run(checkpoints=checkpoints)
    fem_angles = {
        f"{checkpoints[s]:.3f}": fem_flexure_angles(grasp.gripper, v[0]) for s, v in run.checkpoints.items()
    }
    out = run.outcome
    print(
        json.dumps(
            {
                "settings": {k: v for k, v in vars(args).items() if k != "angles"},
                "chain": {
                    "success": bool(chain.success),
                    "lift_mm": round(chain.lift_height * 1e3, 1),
                    "reason": chain.reason,
                },
                "fem": {
                    "success": bool(out.success),
                    "lift_mm": round(out.lift_height * 1e3, 1),
                    "reason": out.reason,
                },
                "fem_wall_s": round(time.perf_counter() - t0, 1),
                "flexure_angles_rad": {"fem": fem_angles, "chain": chain_angles},
            }
        )
    )


if __name__ == "__main__":
    main()
