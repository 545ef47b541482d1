"""Warp kernels of the two-finger FEM grasp with a free rigid object (`mjcodesign.sim.fem.gripper_grasp`).

One explicit step, in launch order: the elastic forces (`mjcodesign.sim.fem.kernels.elastic_forces`
over both fingers' tets), the tendons (`gripper_tendon`), the segments' contact across the flexure
gaps (`gap_contact`), the closest object face of every vertex
(`object_query`: one Warp mesh query per vertex inside the object's box, none elsewhere), the vertex
update with ground and object penalty contact (`gripper_integrate`, which also sums the fingers' wrench
on the object), the object's ground contact (`object_ground`) and the object's update (`object_step`).
The schedule of the open-loop controls (base offsets, tensions, the disturbance) is read at
``step_in`` from tables, so a recorded launch only changes that one integer between steps.

float64 throughout, except the mesh query (Warp meshes are float32). Parameters are grouped inputs
first, then outputs, with ``_in``/``_out`` suffixes, a line per group; the object's state
(`ObjectState`) travels as a struct. This module imports Warp: import it lazily.
"""

from __future__ import annotations

import warp as wp

from mjcodesign.sim.fem.contact_kernels import face_depth, penalty, unit

_f64 = wp.float64
_V3 = wp.array(dtype=wp.vec3d)
_F64 = wp.array(dtype=wp.float64)
_I32 = wp.array(dtype=wp.int32)
Contact = wp.types.vector(length=5, dtype=wp.float64)
"""The finger vertices' contact law: (α [1/s], ke [Pa/m], kd [Pa·s/m], μ, ζ) (`gripper_integrate`)."""
_GAP_MARGIN = 0.25
"""How far past its sides [fraction] a facing cut face still takes a vertex (`gap_contact`)."""


@wp.struct
class ObjectState:
    """The free object's state, world frame, each an array of one.

    COM [m], rotation (quaternion x, y, z, w), COM velocity [m/s], angular velocity [rad/s].
    """

    pos: wp.array(dtype=wp.vec3d)
    rot: wp.array(dtype=wp.quatd)
    vel: wp.array(dtype=wp.vec3d)
    omega: wp.array(dtype=wp.vec3d)


@wp.func
def _waypoint(
    x_in: _V3, idx_in: wp.array2d(dtype=wp.int32), w_in: wp.array2d(dtype=wp.float64), b: int
) -> wp.vec3d:
    p = wp.vec3d()
    for k in range(idx_in.shape[1]):
        p += w_in[b, k] * x_in[idx_in[b, k]]
    return p


# fmt: off
@wp.kernel
def gripper_tendon(
    x_in: _V3, idx_in: wp.array2d(dtype=wp.int32), w_in: wp.array2d(dtype=wp.float64), n_blocks_in: int,
    exit_in: _V3, offset_in: wp.array2d(dtype=wp.vec3d), tension_in: wp.array2d(dtype=wp.float64),
    step_in: int, section_in: wp.array(dtype=wp.vec2i), paper_in: int,
    f_out: _V3,
):  # fmt: on
    """Uniform-tension tendon of each finger [N], one thread per waypoint (finger = waypoint // n_blocks_in).

    The waypoints are the rows ``idx_in``, ``w_in`` (``n_blocks_in`` a finger): the guided routing's one
    per block, or the printed routing's channel points (`mjcodesign.sim.fem.gripper.FemGripper`); the
    anchor ``exit_in`` is the exit point or the base segment's channel entry.

    Frictionless (``paper_in`` 0): waypoint i takes T (u(P_{i−1} − P_i) + u(P_{i+1} − P_i)), the tip
    T u(P_{i−1} − P_i), with T the finger's ``tension_in[step_in]``; the first span starts at the
    finger's exit point ``exit_in`` moved with its base to the start of the substep
    (``offset_in[step_in − 1]``). The authors' law (``paper_in`` 1,
    `mjcodesign.design.tendon_law.tendon_forces` ``paper``): the first waypoint takes nothing, the
    middle ones the frictionless force less its part along their section's axis n (spine top minus
    bottom, vertices ``section_in``), the tip T n. The force is spread back to the vertices by the
    waypoint weights (virtual work).
    """
    b = wp.tid()
    finger = b // n_blocks_in
    i = b - finger * n_blocks_in
    tension = tension_in[step_in, finger]
    p = _waypoint(x_in, idx_in, w_in, b)
    prev = exit_in[finger] + offset_in[step_in - 1, finger]
    if i > 0:
        prev = _waypoint(x_in, idx_in, w_in, b - 1)
    f = tension * unit(prev - p)
    if i < n_blocks_in - 1:
        f = f + tension * unit(_waypoint(x_in, idx_in, w_in, b + 1) - p)
    if paper_in != 0:
        n = unit(x_in[section_in[b][0]] - x_in[section_in[b][1]])
        if i == 0:
            f = wp.vec3d()
        elif i == n_blocks_in - 1:
            f = tension * n
        else:
            f = f - wp.dot(f, n) * n
    for k in range(idx_in.shape[1]):
        wp.atomic_add(f_out, idx_in[b, k], w_in[b, k] * f)


# fmt: off
@wp.kernel
def tendon_servo(
    x_in: _V3, idx_in: wp.array2d(dtype=wp.int32), w_in: wp.array2d(dtype=wp.float64), n_blocks_in: int,
    exit_in: _V3, offset_in: wp.array2d(dtype=wp.vec3d), target_in: wp.array2d(dtype=wp.float64),
    servo_in: wp.vec2d, step_in: int,
    tension_out: wp.array2d(dtype=wp.float64),
):  # fmt: on
    """Position-mode tendon: the pull-only servo spring T = clip(k (ℓ − ℓ*), 0, T_max), one thread a finger.

    ℓ [m] is the finger's tendon length from its exit point (moved with its base, as in
    `gripper_tendon`) through the waypoints; ℓ* = ``target_in[step_in]``; ``servo_in`` = (k [N/m],
    T_max [N]). Writes row ``step_in`` of the tension table that `gripper_tendon` reads.
    """
    finger = wp.tid()
    b0 = finger * n_blocks_in
    prev = exit_in[finger] + offset_in[step_in - 1, finger]
    length = _f64(0.0)
    for i in range(n_blocks_in):
        p = _waypoint(x_in, idx_in, w_in, b0 + i)
        length += wp.length(p - prev)
        prev = p
    tension = servo_in[0] * (length - target_in[step_in, finger])
    tension_out[step_in, finger] = wp.clamp(tension, _f64(0.0), servo_in[1])


@wp.func
def _length_gradient(
    x_in: _V3, idx_in: wp.array2d(dtype=wp.int32), w_in: wp.array2d(dtype=wp.float64), b0: int, i: int,
    n: int, exit_point: wp.vec3d,
) -> wp.vec3d:  # fmt: skip
    """∂ℓ/∂P_i of waypoint i (of n) of the finger whose first waypoint row is b0.

    P_0's previous point is ``exit_point``.
    """
    p = _waypoint(x_in, idx_in, w_in, b0 + i)
    prev = exit_point
    if i > 0:
        prev = _waypoint(x_in, idx_in, w_in, b0 + i - 1)
    g = unit(p - prev)
    if i < n - 1:
        g = g - unit(_waypoint(x_in, idx_in, w_in, b0 + i + 1) - p)
    return g


# fmt: off
@wp.kernel
def tendon_damping(
    x_in: _V3, idx_in: wp.array2d(dtype=wp.int32), w_in: wp.array2d(dtype=wp.float64), n_blocks_in: int,
    exit_in: _V3, offset_in: wp.array2d(dtype=wp.vec3d), mass_in: wp.array(dtype=wp.vec2d),
    flags_in: wp.array(dtype=wp.vec2i), damping_in: wp.float64, step_in: int, dt_in: wp.float64,
    x_out: _V3, v_out: _V3, rate_out: wp.array2d(dtype=wp.float64),
):  # fmt: on
    """Position-mode tendon: the motor's back-EMF damper b ℓ̇ on the tendon, implicit, one thread a finger.

    Runs after `gripper_integrate` and corrects its new velocities and positions in place. With
    J = ∂ℓ/∂x (at the step's start, ``x_in``) and the step's new velocities v*, the damped rate is
    ℓ̇ = J v* / (1 + dt b J M⁻¹ Jᵀ) (b·dt over the tendon's effective mass is ~100 at 2.5 µs, far past
    the explicit limit of 2), and each free waypoint vertex takes Δv = −dt b ℓ̇ M⁻¹ Jᵀ, Δx = dt Δv.
    The anchor (exit point) moves with the base (its known velocity enters J v*). Writes ℓ̇ [m/s] to
    ``rate_out[step_in]``. A finger's waypoints share no free vertex (`FemGripper.tendon_points_disjoint`,
    checked by `mjcodesign.sim.fem.gripper_grasp.FemGrasp`), so J M⁻¹ Jᵀ is the sum of their own terms;
    the fingers share none, so the update is race-free.
    """
    finger = wp.tid()
    n = n_blocks_in
    b0 = finger * n
    e0 = exit_in[finger] + offset_in[step_in - 1, finger]
    e1 = exit_in[finger] + offset_in[step_in, finger]
    rate = wp.dot(unit(e0 - _waypoint(x_in, idx_in, w_in, b0)), (e1 - e0) / dt_in)  # ∂ℓ/∂E = u(E − P_0)
    compliance = _f64(0.0)
    for i in range(n):
        g = _length_gradient(x_in, idx_in, w_in, b0, i, n, e0)
        for k in range(idx_in.shape[1]):
            j = idx_in[b0 + i, k]
            w = w_in[b0 + i, k]
            rate += w * wp.dot(g, v_out[j])
            if flags_in[j][0] == 0:
                compliance += w * w * wp.dot(g, g) / mass_in[j][0]
    rate = rate / (_f64(1.0) + dt_in * damping_in * compliance)
    rate_out[step_in, finger] = rate
    for i in range(n):
        g = _length_gradient(x_in, idx_in, w_in, b0, i, n, e0)
        for k in range(idx_in.shape[1]):
            j = idx_in[b0 + i, k]
            w = w_in[b0 + i, k]
            if flags_in[j][0] == 0 and w != _f64(0.0):  # (a zero weight pads the table)
                dv = (-dt_in * damping_in * rate * w / mass_in[j][0]) * g
                v_out[j] = v_out[j] + dv
                x_out[j] = x_out[j] + dt_in * dv


@wp.kernel
def gap_contact(
    x_in: _V3, vertex_in: _I32, quad_in: wp.array(dtype=wp.vec4i), area_in: _F64, ke_in: wp.float64, f_out: _V3
):
    """Frictionless penalty contact of a cut-face vertex with the facing cut face across a flexure gap.

    The facing face is the rectangle ``quad_in`` (top−, top+, bottom−, bottom+); its outward normal is
    n = u((bottom− − top−) × (top+ − top−)). A vertex below its plane (depth d = −(x − top−)·n > 0)
    and over the rectangle (widened by ``_GAP_MARGIN`` of its sides, and d below its height) is pushed
    out with ke·area·d·n [N]; the facing face's corners take the reaction by bilinear weights, so
    momentum is conserved.
    """
    k = wp.tid()
    q = quad_in[k]
    i = vertex_in[k]
    a = x_in[q[0]]
    e_w = x_in[q[1]] - a
    e_d = x_in[q[2]] - a
    n = unit(wp.cross(e_d, e_w))
    r = x_in[i] - a
    depth = -wp.dot(r, n)
    u = wp.dot(r, e_d) / wp.dot(e_d, e_d)
    v = wp.dot(r, e_w) / wp.dot(e_w, e_w)
    lo = _f64(-_GAP_MARGIN)
    hi = _f64(1.0 + _GAP_MARGIN)
    if depth <= _f64(0.0) or depth > wp.length(e_d) or u < lo or u > hi or v < lo or v > hi:
        return
    f = (ke_in * area_in[k] * depth) * n
    wp.atomic_add(f_out, i, f)
    uc = wp.clamp(u, _f64(0.0), _f64(1.0))
    vc = wp.clamp(v, _f64(0.0), _f64(1.0))
    one = _f64(1.0)
    wp.atomic_sub(f_out, q[0], (one - uc) * (one - vc) * f)
    wp.atomic_sub(f_out, q[1], (one - uc) * vc * f)
    wp.atomic_sub(f_out, q[2], uc * (one - vc) * f)
    wp.atomic_sub(f_out, q[3], uc * vc * f)


# fmt: off
@wp.kernel
def object_query(
    x_in: _V3, flags_in: wp.array(dtype=wp.vec2i), body_in: ObjectState,
    mesh_in: wp.uint64, lower_in: wp.vec3d, upper_in: wp.vec3d, max_dist_in: float,
    face_out: _I32, count_out: _I32,
):  # fmt: on
    """Closest object face of every free vertex inside the object (body-frame mesh query), else −1.

    Only a vertex inside the object's body-frame bounding box (``lower_in``..``upper_in``) is queried;
    ``count_out[0]`` counts the vertices inside. Kept apart from the force kernel so that the adjoint
    treats the face as fixed (piecewise constant), and launched off the tape.
    """
    i = wp.tid()
    face_out[i] = -1
    if flags_in[i][0] != 0:
        return
    xl = wp.quat_rotate_inv(body_in.rot[0], x_in[i] - body_in.pos[0])
    outside = wp.min(xl - lower_in) < _f64(0.0) or wp.max(xl - upper_in) > _f64(0.0)
    if outside:
        return
    q = wp.mesh_query_point_sign_normal(
        mesh_in, wp.vec3(float(xl[0]), float(xl[1]), float(xl[2])), max_dist_in
    )
    if q.result and q.sign < 0.0:
        face_out[i] = q.face
        wp.atomic_add(count_out, 0, 1)


# fmt: off
@wp.kernel
def gripper_integrate(
    x_in: _V3, v_in: _V3, f_in: _V3,
    mass_in: wp.array(dtype=wp.vec2d), area_in: _F64, rest_in: _V3, flags_in: wp.array(dtype=wp.vec2i),
    offset_in: wp.array2d(dtype=wp.vec3d), step_in: int,
    gravity_in: wp.vec3d, contact_in: Contact, dt_in: wp.float64,
    body_in: ObjectState, points_in: _V3, faces_in: wp.array(dtype=wp.vec3i), inv_mass_in: wp.float64,
    face_in: _I32, load_in: _F64,
    x_out: _V3, v_out: _V3, depth_out: _F64, wrench_out: _V3, load_out: _F64,
):  # fmt: on
    """Semi-implicit Euler step of the finger vertices with gravity, mass damping and penalty contact.

    Per vertex: ``mass_in`` (inertial, true) [kg], contact area [m²], rest position [m] and ``flags_in``
    (pinned, finger 0 or 1).

    ``contact_in`` = (α [1/s], ke [Pa/m], kd [Pa·s/m], μ, ζ); ζ > 0 replaces kd by the vertex's own
    damping ratio ζ: area·kd = 2ζ √(ke·area·m), m the vertex's inertial mass. Ground: the plane z = 0. Object: depth below
    the plane of the closest face ``face_in`` (body frame, float64), penalty on the vertex's velocity
    relative to the object's surface. Friction turns viscous below the speed at which one step could
    reverse the sliding velocity of the vertex or of the object under its previous total normal load
    ``load_in[0]`` [N] (`penalty`; ``inv_mass_in`` = 1/m + r²/I_min [1/kg] bounds the object's
    response at radius r); ``load_out[0]`` sums this step's normal forces on the object. The object's
    mesh is ``points_in``, ``faces_in`` (body frame). Gravity acts on the true mass.

    Pinned (base) vertices follow their rest position plus their finger's offset ``offset_in`` at
    ``step_in``.
    ``depth_out`` is the vertex's depth in the object [m] (0 outside); ``wrench_out`` accumulates each
    finger's force [N] and torque about the object's COM [N·m] on the object (finger A in slots 0, 1;
    B in 2, 3; zero it first).
    """
    i = wp.tid()
    zero = _f64(0.0)
    depth_out[i] = zero
    flags = flags_in[i]
    if flags[0] != 0:
        x_new = rest_in[i] + offset_in[step_in, flags[1]]
        v_out[i] = (x_new - x_in[i]) / dt_in
        x_out[i] = x_new
        return
    masses = mass_in[i]
    m = masses[0]
    area = area_in[i]
    v = v_in[i]
    x = x_in[i]
    ke = contact_in[1]
    kd = contact_in[2]
    mu = contact_in[3]
    if contact_in[4] > zero and area > zero:  # interior vertices have no area (and no contact)
        kd = _f64(2.0) * contact_in[4] * wp.sqrt(ke * m / area)
    f = f_in[i] + masses[1] * gravity_in - contact_in[0] * m * v
    if x[2] < zero:
        up = wp.vec3d(zero, zero, _f64(1.0))
        f = f + penalty(v, up, -x[2], area, ke, kd, mu, m, zero, dt_in)
    face = face_in[i]
    if face >= 0:
        rot = body_in.rot[0]
        r = x - body_in.pos[0]
        nd = face_depth(points_in, faces_in, face, wp.quat_rotate_inv(rot, r))
        depth = nd[3]
        if depth > zero:
            n = wp.quat_rotate(rot, wp.vec3d(nd[0], nd[1], nd[2]))
            v_rel = v - body_in.vel[0] - wp.cross(body_in.omega[0], r)
            shared = load_in[0] * inv_mass_in
            fo = penalty(v_rel, n, depth, area, ke, kd, mu, m, shared, dt_in)
            wp.atomic_add(load_out, 0, wp.dot(fo, n))
            f = f + fo
            depth_out[i] = depth
            slot = 2 * flags[1]
            wp.atomic_sub(wrench_out, slot, fo)
            wp.atomic_sub(wrench_out, slot + 1, wp.cross(r, fo))
    v_new = v + dt_in * f / m
    v_out[i] = v_new
    x_out[i] = x + dt_in * v_new


# fmt: off
@wp.kernel
def object_ground(
    points_in: _V3, body_in: ObjectState, inv_mass_in: wp.float64,
    contact_in: wp.vec3d, load_in: _F64, dt_in: wp.float64,
    wrench_out: _V3, count_out: _I32, load_out: _F64,
):  # fmt: on
    """Penalty contact of the object's contact points (body frame) with the ground z = 0.

    ``contact_in`` = (k [N/m], c [N·s/m], μ) per point. Friction turns viscous below the speed at which
    one step could reverse the object's sliding under its previous total normal load ``load_in[0]``
    [N] (`penalty`, ``inv_mass_in`` as in `gripper_integrate`); ``load_out[0]`` sums this step's normal forces on the object. The ground's
    force and torque on the object go to ``wrench_out[4]``, ``wrench_out[5]`` (apart from the
    fingers'); ``count_out[0]`` counts the points below.
    """
    k = wp.tid()
    zero = _f64(0.0)
    r = wp.quat_rotate(body_in.rot[0], points_in[k])
    x = body_in.pos[0] + r
    if x[2] >= zero:
        return
    wp.atomic_add(count_out, 0, 1)
    v = body_in.vel[0] + wp.cross(body_in.omega[0], r)
    up = wp.vec3d(zero, zero, _f64(1.0))
    inv = inv_mass_in
    one = _f64(1.0)
    f = penalty(
        v, up, -x[2], one, contact_in[0], contact_in[1], contact_in[2], one / inv, load_in[0] * inv, dt_in
    )
    wp.atomic_add(load_out, 0, f[2])
    wp.atomic_add(wrench_out, 4, f)
    wp.atomic_add(wrench_out, 5, wp.cross(r, f))


# fmt: off
@wp.kernel
def object_step(
    body_in: ObjectState, wrench_in: _V3, push_in: _V3, step_in: int,
    mass_in: wp.float64, inertia_in: wp.mat33d, gravity_in: wp.vec3d, dt_in: wp.float64,
    body_out: ObjectState,
):  # fmt: on
    """Semi-implicit Euler step of the free object (6 DOF) under gravity, contact and the disturbance.

    Forces: the fingers' and the ground's (``wrench_in`` slots 0, 2, 4; torques about the COM 1, 3, 5)
    and the scheduled push ``push_in[step_in]`` [N] at the COM. ``inertia_in`` is the body-frame inertia
    about the COM [kg·m²]; Euler's equations in the body frame, ω̇ = I⁻¹(τ − ω × Iω).
    """
    rot = body_in.rot[0]
    force = wrench_in[0] + wrench_in[2] + wrench_in[4] + push_in[step_in]
    vel = body_in.vel[0] + dt_in * (force / mass_in + gravity_in)
    w = wp.quat_rotate_inv(rot, body_in.omega[0])
    tau = wp.quat_rotate_inv(rot, wrench_in[1] + wrench_in[3] + wrench_in[5])
    w_dot = wp.inverse(inertia_in) @ (tau - wp.cross(w, inertia_in @ w))
    omega = wp.quat_rotate(rot, w + dt_in * w_dot)
    body_out.pos[0] = body_in.pos[0] + dt_in * vel
    spin = wp.quatd(omega[0], omega[1], omega[2], _f64(0.0))
    body_out.rot[0] = wp.normalize(rot + (_f64(0.5) * dt_in) * (spin * rot))
    body_out.vel[0] = vel
    body_out.omega[0] = omega


@wp.kernel
def accumulate(wrench_in: _V3, weight_in: wp.float64, sum_out: _V3):
    """``sum_out[k] += weight_in · (wrench_in[k] + wrench_in[k + 2])``: both fingers' force, torque (k = 0, 1)."""
    k = wp.tid()
    wp.atomic_add(sum_out, k, weight_in * (wrench_in[k] + wrench_in[k + 2]))
