"""Warp kernels of the tet FEM finger's elasticity (`mjcodesign.sim.fem`), float64 throughout.

Material: stable Neo-Hookean (Smith, de Goes, Kim 2018, "Stable Neo-Hookean Flesh Simulation"),

    Ψ(F) = μ'/2 (I_C − 3) − μ'/2 ln((I_C + 1)/4) + λ'/2 (J − α)²,   α = 1 + 3μ'/(4λ'),

with μ' = 4μ/3 and λ' = λ + 5μ/6, which matches linear elasticity with Lamé μ, λ at small strain
(α makes the rest state stress-free). Linear (4-node) and quadratic (10-node, ``p2_`` prefix) tets:
forces, energy, the finite-difference tangent, and stiffness-proportional damping. The tendon, contact
and explicit-integration kernels are in `mjcodesign.sim.fem.contact_kernels`. This module imports Warp:
import it lazily.

Parameters are grouped inputs first, then outputs, with ``_in``/``_out`` suffixes.
"""

from __future__ import annotations

import warp as wp

_f64 = wp.float64


@wp.func
def _deformation(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, x3: wp.vec3d, dm_inv: wp.mat33d) -> wp.mat33d:
    ds = wp.matrix_from_cols(x1 - x0, x2 - x0, x3 - x0)
    return ds @ dm_inv


@wp.func
def _snh_pk1(f: wp.mat33d, mu: wp.float64, lam: wp.float64) -> wp.mat33d:
    """First Piola–Kirchhoff stress of the stable Neo-Hookean energy [Pa]."""
    one = _f64(1.0)
    ft = wp.transpose(f)
    c0 = ft[0]
    c1 = ft[1]
    c2 = ft[2]
    ic = wp.dot(c0, c0) + wp.dot(c1, c1) + wp.dot(c2, c2)
    j = wp.determinant(f)
    alpha = one + _f64(0.75) * mu / lam
    djdf = wp.matrix_from_cols(wp.cross(c1, c2), wp.cross(c2, c0), wp.cross(c0, c1))
    return f * (mu * (one - one / (ic + one))) + djdf * (lam * (j - alpha))


@wp.func
def _snh_energy(f: wp.mat33d, mu: wp.float64, lam: wp.float64) -> wp.float64:
    """Stable Neo-Hookean energy density [J/m^3], zero at rest."""
    half = _f64(0.5)
    ft = wp.transpose(f)
    ic = wp.dot(ft[0], ft[0]) + wp.dot(ft[1], ft[1]) + wp.dot(ft[2], ft[2])
    j = wp.determinant(f)
    alpha = _f64(1.0) + _f64(0.75) * mu / lam
    return (
        half * mu * (ic - _f64(3.0))
        - half * mu * wp.log((ic + _f64(1.0)) / _f64(4.0))
        + half * lam * ((j - alpha) * (j - alpha) - (_f64(1.0) - alpha) * (_f64(1.0) - alpha))
    )


@wp.func
def _tet_force_matrix(
    x0: wp.vec3d,
    x1: wp.vec3d,
    x2: wp.vec3d,
    x3: wp.vec3d,
    dm_inv: wp.mat33d,
    vol: wp.float64,
    mu: wp.float64,
    lam: wp.float64,
) -> wp.mat33d:
    """Elastic forces on vertices 1..3 as the columns of the result [N]; vertex 0 takes minus their sum."""
    p = _snh_pk1(_deformation(x0, x1, x2, x3, dm_inv), mu, lam)
    return -vol * (p @ wp.transpose(dm_inv))


@wp.kernel
def add_shift(
    a_in: wp.array(dtype=wp.float64), shift_in: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)
):
    """``out = a_in + shift_in`` (a constant shift of the blocks' ln E; the gradient passes through)."""
    i = wp.tid()
    out[i] = a_in[i] + shift_in[i]


@wp.kernel
def lame_parameters(
    log_e_in: wp.array(dtype=wp.float64),
    tet_block_in: wp.array(dtype=wp.int32),
    offset_in: int,
    nu_in: wp.float64,
    mu_out: wp.array(dtype=wp.float64),
    lam_out: wp.array(dtype=wp.float64),
):
    """Per-tet stable Neo-Hookean μ', λ' [Pa] from the blocks' ln(E / Pa) and Poisson's ratio."""
    e = wp.tid()
    young = wp.exp(log_e_in[offset_in + tet_block_in[e]])
    one = _f64(1.0)
    mu = young / (_f64(2.0) * (one + nu_in))
    lam = young * nu_in / ((one + nu_in) * (one - _f64(2.0) * nu_in))
    mu_out[e] = _f64(4.0) / _f64(3.0) * mu
    lam_out[e] = lam + _f64(5.0) / _f64(6.0) * mu


@wp.kernel
def elastic_forces(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    f_out: wp.array(dtype=wp.vec3d),
):
    """Accumulate elastic vertex forces [N] into ``f_out`` (zero it first)."""
    e = wp.tid()
    i0 = tets_in[e, 0]
    i1 = tets_in[e, 1]
    i2 = tets_in[e, 2]
    i3 = tets_in[e, 3]
    h = _tet_force_matrix(
        x_in[i0], x_in[i1], x_in[i2], x_in[i3], dm_inv_in[e], vol_in[e], mu_in[e], lam_in[e]
    )
    ht = wp.transpose(h)
    wp.atomic_add(f_out, i1, ht[0])
    wp.atomic_add(f_out, i2, ht[1])
    wp.atomic_add(f_out, i3, ht[2])
    wp.atomic_sub(f_out, i0, ht[0] + ht[1] + ht[2])


@wp.kernel
def elastic_energy(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    energy_out: wp.array(dtype=wp.float64),
):
    """Accumulate the elastic energy [J] into ``energy_out[0]``."""
    e = wp.tid()
    f = _deformation(
        x_in[tets_in[e, 0]], x_in[tets_in[e, 1]], x_in[tets_in[e, 2]], x_in[tets_in[e, 3]], dm_inv_in[e]
    )
    wp.atomic_add(energy_out, 0, vol_in[e] * _snh_energy(f, mu_in[e], lam_in[e]))


@wp.kernel
def elastic_hessian_fd(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    eps_in: wp.float64,
    k_out: wp.array3d(dtype=wp.float64),
):
    """Per-tet tangent stiffness K = −∂f/∂x [N/m], shape (n_tets, 12, 12), one column per thread.

    Central differences of the analytic forces with step ``eps_in`` [m]; in float64 with eps ≈ 1e-6 of
    the cell size the error is about 1e-9 relative.
    """
    e, col = wp.tid()
    v = col // 3
    a = col - 3 * v
    xs0 = x_in[tets_in[e, 0]]
    xs1 = x_in[tets_in[e, 1]]
    xs2 = x_in[tets_in[e, 2]]
    xs3 = x_in[tets_in[e, 3]]
    d = wp.vec3d()
    d[a] = eps_in
    xp0 = xs0
    xp1 = xs1
    xp2 = xs2
    xp3 = xs3
    xm0 = xs0
    xm1 = xs1
    xm2 = xs2
    xm3 = xs3
    if v == 0:
        xp0 = xs0 + d
        xm0 = xs0 - d
    elif v == 1:
        xp1 = xs1 + d
        xm1 = xs1 - d
    elif v == 2:
        xp2 = xs2 + d
        xm2 = xs2 - d
    else:
        xp3 = xs3 + d
        xm3 = xs3 - d
    hp = _tet_force_matrix(xp0, xp1, xp2, xp3, dm_inv_in[e], vol_in[e], mu_in[e], lam_in[e])
    hm = _tet_force_matrix(xm0, xm1, xm2, xm3, dm_inv_in[e], vol_in[e], mu_in[e], lam_in[e])
    dh = (hm - hp) / (_f64(2.0) * eps_in)
    dht = wp.transpose(dh)
    s = dht[0] + dht[1] + dht[2]
    for k in range(3):
        k_out[e, k, col] = -s[k]
        k_out[e, 3 + k, col] = dht[0][k]
        k_out[e, 6 + k, col] = dht[1][k]
        k_out[e, 9 + k, col] = dht[2][k]


@wp.kernel
def damping_forces(
    v_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    beta_in: wp.float64,
    f_out: wp.array(dtype=wp.vec3d),
):
    """Stiffness-proportional Rayleigh damping, −β K₀ v [N], with K₀ the small-strain stiffness."""
    e = wp.tid()
    i0 = tets_in[e, 0]
    i1 = tets_in[e, 1]
    i2 = tets_in[e, 2]
    i3 = tets_in[e, 3]
    fd = _deformation(v_in[i0], v_in[i1], v_in[i2], v_in[i3], dm_inv_in[e])
    # Linear-elastic stress of the velocity gradient, with the Lamé pair that μ', λ' stand for.
    mu = _f64(0.75) * mu_in[e]
    lam = lam_in[e] - _f64(5.0) / _f64(6.0) * mu
    sym = _f64(0.5) * (fd + wp.transpose(fd))
    p = beta_in * (_f64(2.0) * mu * sym + lam * wp.trace(fd) * wp.identity(n=3, dtype=wp.float64))
    h = -vol_in[e] * (p @ wp.transpose(dm_inv_in[e]))
    ht = wp.transpose(h)
    wp.atomic_add(f_out, i1, ht[0])
    wp.atomic_add(f_out, i2, ht[1])
    wp.atomic_add(f_out, i3, ht[2])
    wp.atomic_sub(f_out, i0, ht[0] + ht[1] + ht[2])


# -- quadratic (10-node) tetrahedra -------------------------------------------------------------------
# Node order: corners 0..3, then edge midpoints (0,1), (1,2), (0,2), (0,3), (1,3), (2,3).
# Quadrature: 4-point rule of degree 2, barycentric (a, b, b, b) and permutations, weights 1/4.
_QA = 0.5854101966249685
_QB = 0.1381966011250105


@wp.func
def _bary(q: int) -> wp.vec4d:
    a = _f64(_QA)
    b = _f64(_QB)
    if q == 0:
        return wp.vec4d(a, b, b, b)
    if q == 1:
        return wp.vec4d(b, a, b, b)
    if q == 2:
        return wp.vec4d(b, b, a, b)
    return wp.vec4d(b, b, b, a)


@wp.func
def _edge(k: int) -> wp.vec2i:
    if k == 0:
        return wp.vec2i(0, 1)
    if k == 1:
        return wp.vec2i(1, 2)
    if k == 2:
        return wp.vec2i(0, 2)
    if k == 3:
        return wp.vec2i(0, 3)
    if k == 4:
        return wp.vec2i(1, 3)
    return wp.vec2i(2, 3)


@wp.func
def _grad_l(dm_inv: wp.mat33d, i: int) -> wp.vec3d:
    """Material gradient of barycentric coordinate i (rows of Dm⁻¹; L0 = 1 − L1 − L2 − L3)."""
    if i == 0:
        return -(dm_inv[0] + dm_inv[1] + dm_inv[2])
    return dm_inv[i - 1]


@wp.func
def _grad_n(dm_inv: wp.mat33d, lq: wp.vec4d, a: int) -> wp.vec3d:
    """Material gradient of the quadratic shape function of node a at barycentric point lq."""
    if a < 4:
        return (_f64(4.0) * lq[a] - _f64(1.0)) * _grad_l(dm_inv, a)
    e = _edge(a - 4)
    return _f64(4.0) * (lq[e[0]] * _grad_l(dm_inv, e[1]) + lq[e[1]] * _grad_l(dm_inv, e[0]))


@wp.func
def _p2_node(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    e: int,
    a: int,
    pert: int,
    d: wp.vec3d,
) -> wp.vec3d:
    x = x_in[tets_in[e, a]]
    if a == pert:
        x = x + d
    return x


@wp.func
def _p2_def(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    e: int,
    dm_inv: wp.mat33d,
    lq: wp.vec4d,
    pert: int,
    d: wp.vec3d,
) -> wp.mat33d:
    f = wp.mat33d()
    for a in range(10):
        f += wp.outer(_p2_node(x_in, tets_in, e, a, pert, d), _grad_n(dm_inv, lq, a))
    return f


@wp.func
def _p2_stress(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    e: int,
    dm_inv: wp.mat33d,
    mu: wp.float64,
    lam: wp.float64,
    q: int,
    pert: int,
    d: wp.vec3d,
) -> wp.mat33d:
    return _snh_pk1(_p2_def(x_in, tets_in, e, dm_inv, _bary(q), pert, d), mu, lam)


@wp.kernel
def p2_elastic_forces(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    f_out: wp.array(dtype=wp.vec3d),
):
    """Quadratic tets: accumulate elastic node forces [N] into ``f_out`` (zero it first)."""
    e, q = wp.tid()
    dm_inv = dm_inv_in[e]
    p = _p2_stress(x_in, tets_in, e, dm_inv, mu_in[e], lam_in[e], q, -1, wp.vec3d())
    w = _f64(0.25) * vol_in[e]
    lq = _bary(q)
    for a in range(10):
        wp.atomic_sub(f_out, tets_in[e, a], w * (p @ _grad_n(dm_inv, lq, a)))


@wp.kernel
def p2_elastic_energy(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    energy_out: wp.array(dtype=wp.float64),
):
    """Quadratic tets: accumulate the elastic energy [J] into ``energy_out[0]``."""
    e, q = wp.tid()
    f = _p2_def(x_in, tets_in, e, dm_inv_in[e], _bary(q), -1, wp.vec3d())
    wp.atomic_add(energy_out, 0, _f64(0.25) * vol_in[e] * _snh_energy(f, mu_in[e], lam_in[e]))


@wp.kernel
def p2_elastic_hessian_fd(
    x_in: wp.array(dtype=wp.vec3d),
    tets_in: wp.array2d(dtype=wp.int32),
    dm_inv_in: wp.array(dtype=wp.mat33d),
    vol_in: wp.array(dtype=wp.float64),
    mu_in: wp.array(dtype=wp.float64),
    lam_in: wp.array(dtype=wp.float64),
    eps_in: wp.float64,
    k_out: wp.array3d(dtype=wp.float64),
):
    """Quadratic tets: K = −∂f/∂x [N/m], shape (n_tets, 30, 30), by central differences per column."""
    e, col = wp.tid()
    v = col // 3
    d = wp.vec3d()
    d[col - 3 * v] = eps_in
    dm_inv = dm_inv_in[e]
    w = _f64(0.25) * vol_in[e] / (_f64(2.0) * eps_in)
    for a in range(10):
        for k in range(3):
            k_out[e, 3 * a + k, col] = _f64(0.0)
    for q in range(4):
        dp = _p2_stress(x_in, tets_in, e, dm_inv, mu_in[e], lam_in[e], q, v, d) - _p2_stress(
            x_in, tets_in, e, dm_inv, mu_in[e], lam_in[e], q, v, -d
        )
        lq = _bary(q)
        for a in range(10):
            g = w * (dp @ _grad_n(dm_inv, lq, a))
            for k in range(3):
                k_out[e, 3 * a + k, col] = k_out[e, 3 * a + k, col] + g[k]
