"""The paper's grasp in the Warp FEM: two FEM fingers on a driven palm, a free rigid object, the ground.

`FemGrasp` takes a MuJoCo `mjcodesign.scenarios.grasp.GraspScene` (design, pose, start openings,
object) and a `GraspScenario`, and steps:

* both fingers (`mjcodesign.sim.fem.gripper.FemGripper`: linear tets, or quadratic ones with
  ``FemOptions(order=2)``; stable Neo-Hookean, ν 0.45,
  one E per block), their base faces clamped to carriages that follow the scenario's opening and lift
  commands through the MuJoCo servos' response (`mjcodesign.sim.fem.schedule`);
* each finger's uniform-tension tendon: through one guided waypoint per block (frictionless law, or
  the authors' law with ``FemOptions(tendon_law="paper")``; the segments' waypoints only with
  ``flexure_guides=False``), or with ``FemOptions(routing="printed")`` through the printed finger's
  channels, the statics' own channel points (`mjcodesign.sim.fem.body.FemBody.path_table`), from the
  base segment's channel entry and straight across every flexure gap (frictionless law): in force mode
  the tension ramped as the scenario ramps it; in position mode the XL330 servo's pull-only spring on
  the FEM's own tendon length (the routing's path), T = clip(k (ℓ − ℓ*), 0, T_max) (`tendon_servo`),
  plus the motor's back-EMF damper b ℓ̇,
  integrated implicitly along the tendon (`tendon_damping`: b·dt over the tendon's effective mass is
  ~100, far past the explicit limit), as MuJoCo's `mjcodesign.scenarios.drive.apply_drive`; and the
  segments' contact across each flexure gap, which carries the tendon's compression once a gap closes;
* the object (`mjcodesign.sim.fem.free_object.FreeObject`) as a free rigid body, 6 DOF;
* penalty contact with Coulomb friction between the finger vertices and the object (signed distance
  from one Warp mesh query per vertex inside the object's box) and the ground, and between the
  object's collision points and the ground; the scheduled disturbance force on the object's COM.

Time step and stabilisation: the paper's 2.5 µs (`FemDynamics`), semi-implicit Euler, mass damping
0.5 /s, selective mass scaling of the vertices whose Gershgorin stiffness bound needs it (gravity on
the true mass; `FemGripper.added_mass_fraction`); friction turns viscous below the speed at which one
step could reverse a sliding velocity (of the vertex, or of the object shared by all its contacts).
A blow-up (non-finite state, a speed over 100 m/s, an inverted tet) ends the run as a `DIVERGED`
outcome naming the time and phase; the state is checked at every MuJoCo step. A run that gains energy
the drivers did not put in is `IMPLAUSIBLE` (`mjcodesign.sim.fem.grasp_energy`), as MuJoCo's.

The forward pass replays recorded launches (`wp.launch(..., record_cmd=True)`): a plain launch costs
~60 µs of Python here, a recorded one ~6 µs, and only the substep index changes between steps.
`FemGrasp.taped_step` launches the same kernels on fresh arrays under a ``wp.Tape``
(`mjcodesign.sim.fem.grasp_adjoint`); both give bitwise the same states (tested).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from mjcodesign.errors import UnsupportedError
from mjcodesign.scenarios.energy import EnergyBalance
from mjcodesign.scenarios.grasp import GraspScenario, GraspScene
from mjcodesign.scenarios.outcome import Failure, failed_outcome
from mjcodesign.sim.fem.free_object import GROUND_CONTACT, FreeObject
from mjcodesign.sim.fem.grasp_energy import EnergyLedger
from mjcodesign.sim.fem.grasp_outcome import FemGraspRun, Frames, grade
from mjcodesign.sim.fem.gripper import FemGripper, quat_matrix
from mjcodesign.sim.fem.options import FemDynamics, FemOptions
from mjcodesign.sim.fem.schedule import grasp_schedule

__all__ = ["FemGrasp", "GRASP_OPTIONS", "GRASP_TENSION"]

_ENERGY_SAMPLES_PER_STEP = 10
"""Samples of the energy bound per MuJoCo step. The drivers' power rings with the fingers' vibration, so
a trapezoid over whole MuJoCo steps aliases it: box/pose0/semi-rigid at 4 µs broke the bound by 0.43 mJ
of 3.1 mJ put in (14%) at one sample a 2 ms step, came within 0.12 of 3.7 mJ (3.4%, inside `ENERGY_TOL`)
at 5, and kept it (excess ≤ 0) at 10 and at 50. 10 a step cost 16% of that rollout's wall time (58.9 s
against 50.6 s without samples, run back to back)."""

GRASP_TENSION = 4.0
"""Default tendon tension of the FEM grasp [N] (the gradient's baseline; the grasp study's
``STUDY_TENSION``): the authors' 100 in their 5x scene at equal bending (T / 25: T ∝ L² at equal E). At
the scenario's default 10 N the soft finger's flexures crush in the FEM (its tets invert within ~80 ms
of tightening: a DIVERGED outcome), a regime no real 0.7 MPa finger reaches."""

GRASP_OPTIONS = FemOptions(h=4e-3, spine_layers=2, waypoint_layers=False)
"""Default mesh of the grasp: 4 mm cells, 2 spine layers, 1,431 vertices per finger (the single-finger
grasp's mesh; no waypoint layers, whose 30 µm layers would cut the stable step tenfold)."""
_QUERY_RANGE = 0.01
"""Largest depth [m] the mesh query searches; a vertex deeper inside the object is not in contact."""
_MAX_SPEED = 100.0
"""A vertex or the object faster than this [m/s] means the explicit step has blown up (the disturbance
gives a 2 g object about 9 m/s)."""


class State(NamedTuple):
    """Warp arrays of one state: finger vertices (x, v) [m, m/s], object COM, rotation, velocities."""

    x: object
    v: object
    pos: object
    rot: object
    vel: object
    omega: object


class Buffers(NamedTuple):
    """Warp arrays one step writes besides the next state."""

    f: object
    """Vertex forces [N] (elastic and tendon), (n,)."""
    face: object
    """Closest object face of every vertex inside the object, else −1, (n,)."""
    count: object
    """Vertices inside the object, (1,)."""
    depth: object
    """Depth of every vertex in the object [m], (n,)."""
    wrench: object
    """On the object: finger A's force, torque; finger B's; the ground's [N, N·m], (6,)."""
    ground: object
    """Object points below the ground, (1,)."""
    load: object
    """Total normal force on the object this substep [N] (1,); read by the next substep's friction."""


class FemGrasp:
    """One FEM grasp of ``scene``'s object by ``scene``'s design at its pose, following ``scenario``.

    ``gripper`` reuses a built `FemGripper` of the same geometry, mesh and step (its ln E is set to
    the scene's design).
    """

    def __init__(
        self,
        scene: GraspScene,
        scenario: GraspScenario,
        *,
        options: FemOptions | None = None,
        dynamics: FemDynamics | None = None,
        gripper: FemGripper | None = None,
    ):
        from mjcodesign.sim.fem import grasp_kernels

        self.kernels = grasp_kernels
        self.scene, self.scenario = scene, scenario
        dyn = self.dyn = dynamics or FemDynamics()
        if scenario.friction is not None and scenario.friction != dyn.friction:
            raise UnsupportedError(
                f"the FEM grasp's finger-object friction is FemDynamics.friction ({dyn.friction:g}), "
                f"not the scenario's ({scenario.friction:g}): set it there"
            )
        if gripper is None:
            gripper = FemGripper(
                scene.built.design, scene.built.stiffness, options=options or GRASP_OPTIONS, dt=dyn.dt
            )
        else:
            gripper.set_log_e(scene.built.stiffness.log_e)
        self.gripper = g = gripper
        wp = self.wp = g.wp
        dev = self.dev = g.device
        self.schedule = sch = grasp_schedule(scene, scenario, dyn.dt)
        self.object = obj = FreeObject(scene.obj, device=dev)
        self.placement = pl = g.place(scene.pose, scene.start_openings)
        self.energy_stride = max(1, sch.per_step // _ENERGY_SAMPLES_PER_STEP)
        """Substeps between the energy bound's samples (`mjcodesign.sim.fem.grasp_energy`)."""
        f64 = wp.float64
        arr = lambda a, t: wp.array(a, dtype=t, device=dev)  # noqa: E731
        gravity = np.asarray(dyn.gravity, dtype=float)
        flags = arr(np.column_stack([g.pinned, g.finger_of]), wp.vec2i)
        self._flags = flags
        # per vertex: (inertial, true) mass, contact area, rest position, (pinned, finger)
        self._vertices = [arr(np.column_stack([g.inertial, g.mass]), wp.vec2d), arr(g.area, wp.float64)]
        self._vertices += [arr(pl.vertices, wp.vec3d), flags]
        self.base_offsets = sch.offsets(pl.axes)
        """Each finger's base offset from its placement at the end of every substep [m], (n_steps + 1, 2, 3)."""
        self._offsets = arr(self.base_offsets, wp.vec3d)
        self._surface = [obj.mesh_points, obj.mesh_faces, f64(obj.inv_mass_bound)]
        self._tendon = [
            arr(g.waypoint_idx, wp.int32),
            arr(g.waypoint_w, wp.float64),
            g.n_waypoints,
            arr(pl.exits, wp.vec3d),
            self._offsets,
            arr(sch.tension, wp.float64),
        ]
        self._law = [arr(g.waypoint_section, wp.vec2i), int(g.options.tendon_law == "paper")]
        self._gaps = [
            arr(g.gaps.vertex, wp.int32),
            arr(g.gaps.quad, wp.vec4i),
            arr(g.gaps.area, wp.float64),
            f64(g.gap_ke),
        ]
        self.position_mode = sch.servo is not None
        """The tendon is the position servo (`TendonPosition`), not a fixed tension."""
        if self.position_mode:
            if not g.tendon_points_disjoint():
                raise UnsupportedError(
                    "the position servo's implicit damper needs each tendon point on its own free vertices; "
                    "two points of this mesh's tendon share one (another cell size moves them apart)"
                )
            k, t_max, b = sch.servo
            slack = self.tendon_lengths(pl.vertices, 0)  # ℓ₀: the FEM tendon at rest, straight fingers
            self._servo = [arr(slack[None, :] - sch.wound[:, None], wp.float64), wp.vec2d(k, t_max)]
            self._damping = [arr(np.column_stack([g.inertial, g.mass]), wp.vec2d), flags, f64(b)]
            rate = np.full((sch.n_steps + 1, 2), np.nan)  # a substep not taken stays NaN
            rate[0] = 0.0
            self._rate = arr(rate, wp.float64)
        self._push = arr(sch.push, wp.vec3d)
        self._box = (wp.vec3d(*obj.lower), wp.vec3d(*obj.upper))
        self._contact = grasp_kernels.Contact(
            dyn.mass_damping, dyn.contact_ke, dyn.contact_kd, dyn.friction, dyn.contact_damping_ratio
        )
        self._ground = wp.vec3d(*GROUND_CONTACT)
        self._gravity = wp.vec3d(*gravity)
        self._body = [f64(obj.mass), wp.mat33d(*obj.inertia.ravel()), self._gravity]
        self._dt = f64(dyn.dt)
        self._hold_weight = f64(1.0 / (sch.hold[1] - sch.hold[0] + 1))

    # -- state and buffers ------------------------------------------------------------------------
    def initial_state(self) -> State:
        """The state at t = 0: fingers at rest at the start openings, object at rest on the ground."""
        return self.state_from(
            (
                self.placement.vertices,
                np.zeros_like(self.placement.vertices),
                self.object.start,
                np.array([0.0, 0.0, 0.0, 1.0]),
                np.zeros(3),
                np.zeros(3),
            )
        )

    def state_from(self, arrays, *, requires_grad: bool = False) -> State:
        """A `State` of Warp arrays from numpy (x, v, pos, quaternion (x, y, z, w), vel, omega)."""
        wp = self.wp
        types = (wp.vec3d, wp.vec3d, wp.vec3d, wp.quatd, wp.vec3d, wp.vec3d)
        return State(
            *(
                wp.array(
                    np.asarray(a, dtype=float).reshape(-1, *np.shape(a)[-1:]),
                    dtype=t,
                    device=self.dev,
                    requires_grad=requires_grad,
                )
                for a, t in zip(arrays, types, strict=True)
            )
        )

    def empty_state(self, *, requires_grad: bool = False) -> State:
        """A `State` filled with NaN (an output that a kernel fails to write stays NaN)."""
        n = self.gripper.n_vertices
        nan = np.nan
        return self.state_from(
            (
                np.full((n, 3), nan),
                np.full((n, 3), nan),
                np.full(3, nan),
                np.full(4, nan),
                np.full(3, nan),
                np.full(3, nan),
            ),
            requires_grad=requires_grad,
        )

    def buffers(self, *, requires_grad: bool = False) -> Buffers:
        """Fresh step buffers: accumulators zeroed, per-vertex outputs NaN-filled (``depth``), faces −2."""
        wp = self.wp
        n = self.gripper.n_vertices
        dev = self.dev
        return Buffers(
            f=wp.zeros(n, dtype=wp.vec3d, device=dev, requires_grad=requires_grad),
            face=wp.full(n, -2, dtype=wp.int32, device=dev),
            count=wp.zeros(1, dtype=wp.int32, device=dev),
            depth=wp.full(n, np.nan, dtype=wp.float64, device=dev, requires_grad=requires_grad),
            wrench=wp.zeros(6, dtype=wp.vec3d, device=dev, requires_grad=requires_grad),
            ground=wp.zeros(1, dtype=wp.int32, device=dev),
            load=wp.zeros(1, dtype=wp.float64, device=dev, requires_grad=requires_grad),
        )

    # -- one step ---------------------------------------------------------------------------------
    def launches(self, a: State, b: State, buf: Buffers, load_prev, s: int) -> list[tuple]:
        """The launches of substep ``s`` from state ``a`` to ``b``: (kernel, dim, inputs, outputs, taped).

        ``load_prev`` holds the object's total normal load of the previous substep [N] (it sets where
        friction turns viscous). ``taped`` is False for the mesh query (its faces are held fixed by the
        adjoint).
        """
        k = self.kernels
        g = self.gripper
        o = self.object
        n = g.n_vertices
        body_a, body_b = self.body(a), self.body(b)
        servo = []
        if self.position_mode:  # the servo's tension from the tendon length, into the tension table
            servo = [(k.tendon_servo, 2, [a.x, *self._tendon[:5], *self._servo, s], [self._tendon[5]], False)]
        out = [
            (*g.force_launch(a.x, buf.f), True),
            *servo,
            (k.gripper_tendon, 2 * g.n_waypoints, [a.x, *self._tendon, s, *self._law], [buf.f], True),
            (k.gap_contact, len(g.gaps.vertex), [a.x, *self._gaps], [buf.f], True),
            (
                k.object_query,
                n,
                [a.x, self._flags, body_a, o.mesh.id, *self._box, _QUERY_RANGE],
                [buf.face, buf.count],
                False,
            ),
            (
                k.gripper_integrate,
                n,
                [
                    *(a.x, a.v, buf.f, *self._vertices, self._offsets, s),
                    *(self._gravity, self._contact, self._dt, body_a, *self._surface, buf.face, load_prev),
                ],
                [b.x, b.v, buf.depth, buf.wrench, buf.load],
                True,
            ),
            (
                k.object_ground,
                len(o.points),
                [o.ground_points, body_a, self._surface[2], self._ground, load_prev, self._dt],
                [buf.wrench, buf.ground, buf.load],
                True,
            ),
            (k.object_step, 1, [body_a, buf.wrench, self._push, s, *self._body, self._dt], [body_b], True),
        ]
        if self.position_mode:  # the motor's damper, implicit, after the vertex update (in place)
            damp = (
                k.tendon_damping,
                2,
                [a.x, *self._tendon[:5], *self._damping, s, self._dt],
                [b.x, b.v, self._rate],
                False,
            )
            out.insert(next(i for i, x in enumerate(out) if x[0] is k.gripper_integrate) + 1, damp)
        return out

    def body(self, st: State):
        """The object's part of ``st`` as the kernels' `ObjectState` struct."""
        out = self.kernels.ObjectState()
        out.pos, out.rot, out.vel, out.omega = st.pos, st.rot, st.vel, st.omega
        return out

    def taped_step(self, a: State, s: int, load_prev, hold_sum=None) -> tuple[State, Buffers]:
        """Substep ``s`` from ``a`` into fresh arrays (for a ``wp.Tape``); adds to ``hold_sum`` in the hold.

        ``load_prev``: the previous substep's ``Buffers.load``; the step's own is in the returned buffers.
        """
        wp = self.wp
        b = self.empty_state(requires_grad=True)
        buf = self.buffers(requires_grad=True)
        for kernel, dim, inputs, outputs, taped in self.launches(a, b, buf, load_prev, s):
            wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.dev, record_tape=taped)
        if hold_sum is not None and self.in_hold(s):
            wp.launch(
                self.kernels.accumulate,
                dim=2,
                inputs=[buf.wrench, self._hold_weight],
                outputs=[hold_sum],
                device=self.dev,
            )
        return b, buf

    def in_hold(self, s: int) -> bool:
        """True if substep ``s`` is inside the body-force average."""
        return self.schedule.hold[0] <= s <= self.schedule.hold[1]

    # -- the forward pass -------------------------------------------------------------------------
    def run(self, *, checkpoints=(), steps: int | None = None) -> FemGraspRun:
        """Roll the grasp out; ``checkpoints`` are substeps whose start states are kept (numpy).

        A blow-up (non-finite state, or a speed past ``_MAX_SPEED``) ends the run early; its outcome is
        `Failure.DIVERGED` with the time and phase. ``steps`` stops after that many substeps (a partial
        run has no outcome).
        """
        t0 = time.perf_counter()
        wp = self.wp
        sch = self.schedule
        J = sch.per_step
        states = [self.initial_state(), self.empty_state()]
        buf = self.buffers()
        load = [wp.zeros(1, dtype=wp.float64, device=self.dev) for _ in range(2)]
        hold_sum = wp.zeros(2, dtype=wp.vec3d, device=self.dev)
        cmds = []
        for p in range(2):
            row = []
            for kernel, dim, inputs, outputs, _ in self.launches(
                states[p], states[1 - p], buf._replace(load=load[1 - p]), load[p], 1
            ):
                row.append(
                    wp.launch(
                        kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.dev, record_cmd=True
                    )
                )
            cmds.append(row)
        stepped = [i for i, c in enumerate(cmds[0]) if "step_in" in (a.label for a in c.kernel.adj.args)]
        acc = wp.launch(
            self.kernels.accumulate,
            dim=2,
            inputs=[buf.wrench, self._hold_weight],
            outputs=[hold_sum],
            device=self.dev,
            record_cmd=True,
        )
        frames = Frames.empty(sch.n_steps // J + 1)
        frames.record(0, 0.0, states[0], buf, initial=True)
        ledger = EnergyLedger(self)
        ledger.sample(0, states[0])
        kept: dict[int, tuple] = {}
        failure = None
        n_steps = sch.n_steps if steps is None else min(int(steps), sch.n_steps)
        checkpoints = set(checkpoints)
        for s in range(1, n_steps + 1):
            p = (s - 1) % 2
            if s in checkpoints:
                kept[s] = (*(a.numpy().copy() for a in states[p]), float(load[p].numpy()[0]))
            buf.f.zero_()
            buf.count.zero_()
            buf.wrench.zero_()
            buf.ground.zero_()
            load[1 - p].zero_()
            for i in stepped:
                cmds[p][i].set_param_by_name("step_in", s)
            for c in cmds[p]:
                c.launch()
            if self.in_hold(s):
                acc.launch()
            if s % J == 0:
                frames.record(s // J, s * sch.dt, states[1 - p], buf)
                failure = self._blow_up(states[1 - p], s * sch.dt)
                if failure is not None:
                    break
            if s % self.energy_stride == 0:
                ledger.sample(s, states[1 - p])
        final = states[s % 2]
        return self._finish(
            frames.cut(s // J + 1), hold_sum.numpy().copy(), final, s, kept, failure, t0, ledger.balance()
        )

    def _finish(
        self, frames: Frames, hold_sum, final: State, s_done: int, kept, failure, t0, energy: EnergyBalance
    ) -> FemGraspRun:
        """The run's record and outcome (`mjcodesign.sim.fem.grasp_outcome.grade`)."""
        sch = self.schedule
        J = sch.per_step
        depth = self.depths(final)
        ground = self.ground_points(final)
        wall = time.perf_counter() - t0
        if failure is not None:
            outcome = failed_outcome(Failure.DIVERGED, failure, wall)
        elif s_done < sch.n_steps:
            outcome = None
        else:
            R = self.placement.rotation
            body_force = np.r_[R.T @ hold_sum[1], R.T @ hold_sum[0]]
            rel = [R.T @ (frames.pos[s // J] - self.palm(s)) for s in (sch.grasp_step, sch.n_steps)]
            rise = float(frames.pos[-1, 2] - frames.pos[0, 2])
            path = frames.pos[[s // J for s in sch.samples]]
            outcome = grade(
                body_force, rel[1] - rel[0], rise, ground > 0, bool((depth > 0).any()), self.scenario, path,
                energy=energy, mujoco_dt=J * sch.dt,
            ).with_wall_time(wall)  # fmt: skip
        return FemGraspRun(
            outcome=outcome,
            frames=frames,
            hold_wrench=np.r_[hold_sum[1], hold_sum[0]],
            final_x=final.x.numpy().copy(),
            final_depth=depth,
            ground_points=ground,
            substeps=s_done,
            dt=sch.dt,
            n_vertices=self.gripper.n_vertices,
            added_mass_fraction=self.gripper.added_mass_fraction,
            wall_time_s=wall,
            starts=dict(sch.starts),
            checkpoints=kept,
            energy=energy,
        )

    def _blow_up(self, st: State, t: float) -> str | None:
        """Why the state ``st`` at time ``t`` [s] is a blow-up (the reason of a DIVERGED outcome), or None.

        Non-finite values, a speed past ``_MAX_SPEED`` or an inverted tet (J ≤ 0: a crushed element,
        which the explicit step cannot recover from).
        """
        x, v = st.x.numpy(), st.v.numpy()
        sch = self.schedule
        if not (np.isfinite(x).all() and np.isfinite(v).all() and np.isfinite(st.pos.numpy()).all()):
            what = "non-finite state"
        elif max(float(np.abs(v).max()), float(np.abs(st.vel.numpy()).max())) > _MAX_SPEED:
            what = f"speed over {_MAX_SPEED:g} m/s"
        else:
            j = self.gripper.volume_ratio(x)
            if j.min() > 0.0:
                return None
            nb = self.gripper.n_blocks
            block = int(self.gripper.tet_block_np[int(np.argmin(j))])
            what = (
                f"inverted tetrahedra ({int(np.sum(j <= 0))}; finger {'AB'[block // nb]} block {block % nb})"
            )
        step = int(round(t / sch.dt)) // sch.per_step
        phase = max(
            (k for k, v0 in sch.starts.items() if k != "end" and v0 <= step), key=lambda k: sch.starts[k]
        )
        return f"diverged: FEM {what} at t = {t:.4f} s ({phase})"

    # -- measurements -----------------------------------------------------------------------------
    def tendon_lengths(self, x: np.ndarray, s: int) -> np.ndarray:
        """Each finger's tendon length [m] at vertex positions ``x`` (n, 3) and the bases of substep ``s``.

        From the anchor (the exit point or the base segment's channel entry, moved with its base) through
        the tendon's points (`FemOptions.routing`), as the kernels measure it.
        """
        g = self.gripper
        nb = g.n_waypoints
        pts = np.einsum("bk,bkj->bj", g.waypoint_w, np.asarray(x)[g.waypoint_idx])
        offsets = self.base_offsets[s]
        out = np.empty(2)
        for f in range(2):
            path = np.vstack([self.placement.exits[f] + offsets[f], pts[f * nb : (f + 1) * nb]])
            out[f] = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
        return out

    def tendon_forces(self, x: np.ndarray, s: int) -> np.ndarray:
        """The tendons' vertex forces [N] (n, 3) at positions ``x`` (n, 3; numpy or Warp) in substep ``s`` (≥ 1).

        One launch of the step's own tendon kernel (`FemOptions.tendon_law`, force mode: the
        tension table's row ``s``).
        """
        wp = self.gripper.wp
        dev = self.gripper.device
        xa = self.gripper.warp_positions(x)
        f = wp.zeros(len(x), dtype=wp.vec3d, device=dev)
        wp.launch(
            self.kernels.gripper_tendon,
            dim=2 * self.gripper.n_waypoints,
            inputs=[xa, *self._tendon, int(s), *self._law],
            outputs=[f],
            device=dev,
        )
        return f.numpy()

    def tendon_history(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The last run's tendon tensions and, in position mode, tendon rates.

        (tension [N], shape (n_steps + 1, 2), row s: substep s; the rate ℓ̇ [m/s] the position servo's
        damper saw, same shape, or None in force mode).
        """
        rate = self._rate.numpy().copy() if self.position_mode else None
        return self._tendon[5].numpy().copy(), rate

    def palm(self, s: int) -> np.ndarray:
        """Palm position [m] at the end of substep ``s``."""
        return self.placement.palm + np.array([0.0, 0.0, self.schedule.lift[s]])

    def depths(self, st: State) -> np.ndarray:
        """Depth [m] of every finger vertex inside the object in state ``st`` (0 outside), (n,)."""
        wp = self.wp
        o = self.object
        n = self.gripper.n_vertices
        face = wp.full(n, -2, dtype=wp.int32, device=self.dev)
        count = wp.zeros(1, dtype=wp.int32, device=self.dev)
        query = self.kernels.object_query
        _, dim, inputs, _, _ = next(
            x for x in self.launches(st, st, self.buffers(), count, 1) if x[0] is query
        )
        kernel = query
        wp.launch(kernel, dim=dim, inputs=inputs, outputs=[face, count], device=self.dev)
        face = face.numpy()
        inside = np.flatnonzero(face >= 0)
        out = np.zeros(n)
        if inside.size:
            R = _rotation(st.rot.numpy()[0])
            xl = (st.x.numpy()[inside] - st.pos.numpy()[0]) @ R
            pts = o.mesh_points.numpy()
            tri = pts[o.mesh_faces.numpy()[face[inside]]]
            nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            out[inside] = np.maximum(np.einsum("ij,ij->i", tri[:, 0] - xl, nrm), 0.0)
        return out

    def ground_points(self, st: State) -> int:
        """Object collision points below the ground in state ``st``."""
        z = (self.object.points @ _rotation(st.rot.numpy()[0]).T)[:, 2] + st.pos.numpy()[0, 2]
        return int(np.count_nonzero(z < 0.0))


def _rotation(q_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrix of a Warp quaternion (x, y, z, w)."""
    x, y, z, w = q_xyzw
    return quat_matrix((w, x, y, z))
