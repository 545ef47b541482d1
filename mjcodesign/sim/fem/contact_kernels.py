"""Warp kernels of the FEM finger's explicit dynamics (`mjcodesign.sim.fem`), float64 throughout.

The tendon at its waypoints (`waypoints`, `tendon_forces`, `scatter_waypoint_forces`), penalty contact
with the ground and a static rigid object (`closest_face`, `object_contact_static`) and the one explicit
step every rollout takes (`integrate`: `mjcodesign.sim.fem.finger.FemFinger.rollout` on the ground alone,
`mjcodesign.sim.fem.contact.FemContact` with an object). The elastic kernels are in
`mjcodesign.sim.fem.kernels`. This module imports Warp: import it lazily.

Parameters are grouped inputs first, then outputs, with ``_in``/``_out`` suffixes.
"""

from __future__ import annotations

import warp as wp

_f64 = wp.float64


@wp.kernel
def waypoints(
    x_in: wp.array(dtype=wp.vec3d),
    idx_in: wp.array2d(dtype=wp.int32),
    w_in: wp.array2d(dtype=wp.float64),
    p_out: wp.array(dtype=wp.vec3d),
):
    """Tendon waypoints [m] as weighted sums of vertices (rows padded with weight 0), one per block."""
    b = wp.tid()
    p = wp.vec3d()
    for k in range(idx_in.shape[1]):
        p += w_in[b, k] * x_in[idx_in[b, k]]
    p_out[b] = p


@wp.func
def unit(v: wp.vec3d) -> wp.vec3d:
    """``v / |v|``, or ``v / 1e-15`` for a null vector (no division by zero, also in the adjoint)."""
    return v / wp.max(wp.length(v), _f64(1e-15))


@wp.kernel
def tendon_forces(
    p_in: wp.array(dtype=wp.vec3d),
    exit_in: wp.vec3d,
    tension_in: wp.float64,
    f_out: wp.array(dtype=wp.vec3d),
):
    """Frictionless tendon [N] at each waypoint: f_T (u(P_{i−1} − P_i) + u(P_{i+1} − P_i)), tip anchored."""
    i = wp.tid()
    n = p_in.shape[0]
    p = p_in[i]
    prev = exit_in
    if i > 0:
        prev = p_in[i - 1]
    if i == n - 1:
        f_out[i] = tension_in * unit(prev - p)
    else:
        f_out[i] = tension_in * (unit(prev - p) + unit(p_in[i + 1] - p))


@wp.kernel
def scatter_waypoint_forces(
    f_wp_in: wp.array(dtype=wp.vec3d),
    idx_in: wp.array2d(dtype=wp.int32),
    w_in: wp.array2d(dtype=wp.float64),
    f_out: wp.array(dtype=wp.vec3d),
):
    """Spread waypoint forces back to the vertices by the same weights (virtual work): f += Wᵀ F."""
    b = wp.tid()
    for k in range(idx_in.shape[1]):
        wp.atomic_add(f_out, idx_in[b, k], w_in[b, k] * f_wp_in[b])


@wp.kernel
def closest_face(
    x_in: wp.array(dtype=wp.vec3d),
    mesh_in: wp.uint64,
    max_dist_in: float,
    face_out: wp.array(dtype=wp.int32),
):
    """Closest object face of every vertex inside the object (Warp mesh query, float32), else −1.

    Kept apart from the force kernels so that the adjoint treats the face as fixed (piecewise-constant),
    not through the query's own adjoint.
    """
    i = wp.tid()
    x = x_in[i]
    q = wp.mesh_query_point_sign_normal(mesh_in, wp.vec3(float(x[0]), float(x[1]), float(x[2])), max_dist_in)
    face_out[i] = -1
    if q.result and q.sign < 0.0:
        face_out[i] = q.face


@wp.func
def face_depth(
    points_in: wp.array(dtype=wp.vec3d),
    faces_in: wp.array(dtype=wp.vec3i),
    face: int,
    x: wp.vec3d,
) -> wp.vec4d:
    """(outward normal, depth) [m] of ``x`` against the plane of object face ``face`` (float64)."""
    tri = faces_in[face]
    a = points_in[tri[0]]
    n = unit(wp.cross(points_in[tri[1]] - a, points_in[tri[2]] - a))
    return wp.vec4d(n[0], n[1], n[2], wp.dot(a - x, n))


@wp.func
def penalty(
    v: wp.vec3d,
    n: wp.vec3d,
    depth: wp.float64,
    area: wp.float64,
    ke: wp.float64,
    kd: wp.float64,
    mu: wp.float64,
    m: wp.float64,
    extra: wp.float64,
    dt: wp.float64,
) -> wp.vec3d:
    """Penalty contact force [N] on a vertex of mass ``m``.

    Normal: area·(ke·depth + kd·approach speed) along n. Coulomb friction μ·fn, viscous below the speed
    v_s = max(1 mm/s, 2 μ dt (fn / m + extra)); ``extra`` [m/s²] is the acceleration that the other
    contacts of a free body give it (0 against the ground or a static body).

    The viscous branch has rate μ fn / (v_s m) ≤ 1 / (2 dt), so one explicit step never reverses the
    sliding velocity (no stick–slip chatter, and a bounded adjoint).
    """
    vn = wp.dot(v, n)
    fn = wp.max(area * (ke * depth - kd * wp.min(vn, _f64(0.0))), _f64(0.0))
    vt = v - vn * n
    two = _f64(2.0)
    v_s = wp.max(_f64(1e-3), two * mu * fn * dt / m + two * mu * dt * extra)
    # |vt| from its square, floored first: the adjoint of a length at zero would divide by zero.
    speed = wp.sqrt(wp.max(wp.dot(vt, vt), v_s * v_s))
    return fn * n - vt * (mu * fn / speed)


@wp.kernel
def integrate(
    x_in: wp.array(dtype=wp.vec3d),
    v_in: wp.array(dtype=wp.vec3d),
    f_in: wp.array(dtype=wp.vec3d),
    mass_in: wp.array(dtype=wp.float64),
    weight_in: wp.array(dtype=wp.vec3d),
    area_in: wp.array(dtype=wp.float64),
    pinned_in: wp.array(dtype=wp.int32),
    x_pinned_in: wp.array(dtype=wp.vec3d),
    offset_in: wp.vec3d,
    alpha_in: wp.float64,
    ke_in: wp.float64,
    kd_in: wp.float64,
    friction_in: wp.float64,
    points_in: wp.array(dtype=wp.vec3d),
    faces_in: wp.array(dtype=wp.vec3i),
    face_in: wp.array(dtype=wp.int32),
    dt_in: wp.float64,
    x_out: wp.array(dtype=wp.vec3d),
    v_out: wp.array(dtype=wp.vec3d),
    f_object_out: wp.array(dtype=wp.vec3d),
    impulse_out: wp.array(dtype=wp.float64),
):
    """Semi-implicit Euler step with gravity, mass damping and penalty contact: the one explicit step.

    Gravity is ``weight_in`` [N] (the true mass). Contact is against the ground z = 0 and, where a vertex
    has one, a static rigid object: depth below the plane of the closest face ``face_in`` found by
    `closest_face` (−1 outside, or everywhere when there is no object). Both use the penalty of
    :func:`penalty` (pressure ke·depth + kd·approach speed on the vertex's lumped area ``area_in``,
    Coulomb friction μ, viscous below a speed that keeps one explicit step from reversing the sliding
    velocity).

    ``mass_in`` is the inertial (possibly mass-scaled) mass. ``f_object_out`` is the object's contact
    force on each vertex [N]; ``impulse_out[0]`` accumulates the object's normal force times dt [N·s].
    Pinned vertices follow ``x_pinned_in + offset_in`` (clamped base, driven for lift) and feel no
    contact.
    """
    i = wp.tid()
    zero = _f64(0.0)
    if pinned_in[i] != 0:
        x_new = x_pinned_in[i] + offset_in
        v_out[i] = (x_new - x_in[i]) / dt_in
        x_out[i] = x_new
        f_object_out[i] = wp.vec3d(zero, zero, zero)
        return
    m = mass_in[i]
    v = v_in[i]
    x = x_in[i]
    f = f_in[i] + weight_in[i] - alpha_in * m * v
    if x[2] < zero:
        up = wp.vec3d(zero, zero, _f64(1.0))
        f = f + penalty(v, up, -x[2], area_in[i], ke_in, kd_in, friction_in, m, zero, dt_in)
    fo = wp.vec3d(zero, zero, zero)
    if face_in[i] >= 0:
        nd = face_depth(points_in, faces_in, face_in[i], x)
        if nd[3] > zero:
            n = wp.vec3d(nd[0], nd[1], nd[2])
            fo = penalty(v, n, nd[3], area_in[i], ke_in, kd_in, friction_in, m, zero, dt_in)
            wp.atomic_add(impulse_out, 0, dt_in * wp.dot(fo, n))
    f_object_out[i] = fo
    v_new = v + dt_in * (f + fo) / m
    v_out[i] = v_new
    x_out[i] = x + dt_in * v_new


@wp.kernel
def object_contact_static(
    x_in: wp.array(dtype=wp.vec3d),
    area_in: wp.array(dtype=wp.float64),
    pinned_in: wp.array(dtype=wp.int32),
    ke_in: wp.float64,
    points_in: wp.array(dtype=wp.vec3d),
    faces_in: wp.array(dtype=wp.vec3i),
    face_in: wp.array(dtype=wp.int32),
    f_out: wp.array(dtype=wp.vec3d),
    k_out: wp.array(dtype=wp.mat33d),
):
    """Frictionless penalty contact of a static equilibrium.

    Force area·ke·depth·n [N] and stiffness area·ke·n nᵀ [N/m] (−∂f/∂x with the closest face fixed).
    """
    i = wp.tid()
    zero = _f64(0.0)
    f_out[i] = wp.vec3d(zero, zero, zero)
    k_out[i] = wp.mat33d()
    if pinned_in[i] != 0 or face_in[i] < 0:
        return
    nd = face_depth(points_in, faces_in, face_in[i], x_in[i])
    if nd[3] > zero:
        n = wp.vec3d(nd[0], nd[1], nd[2])
        k = area_in[i] * ke_in
        f_out[i] = k * nd[3] * n
        k_out[i] = k * wp.outer(n, n)
