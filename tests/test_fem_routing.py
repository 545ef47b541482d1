"""The Warp FEM's printed tendon routing: channel points in the mesh, the tendon's load, its buckling tension.

Machinery on a coarse mesh (seconds); the chain's printed routing against the converged FEM reads the
record of ``scripts/fem_routing_record.py`` (``tests/data/fem_routing_*.json``) and never reruns the FEM.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.crosscheck.calibration import CONVERGED_MESH, TRAIN_SEEDS
from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, MeshError
from mjcodesign.models import build_finger
from mjcodesign.models.channels import channel_points
from mjcodesign.models.stability import buckling_tension, string_buckling_tension
from mjcodesign.models.types import FingerModel, SimOptions
from mjcodesign.scenarios.static import curl

pytest.importorskip("warp")

from mjcodesign.sim.fem import FemFinger, FemOptions  # noqa: E402
from mjcodesign.sim.fem.mesh import embed_points, mesh_finger, to_quadratic  # noqa: E402

_DATA = Path(__file__).parent / "data"
_COARSE = {"h": 4e-3, "spine_layers": 2}
_PRINTED = SimOptions(routing="printed", gravity=False, hinges_per_block=1)  # one hinge between guides
_TOL_EMBED = 1e-15  # [m]: W @ X against the channel points, round-off of positions ~0.1 m
_TOL_FD_FORCE = 1e-6  # f·v against −T dℓ/dv by central differences (step 1e-6 m on 10 mm spans)
_TOL_FD_JAC = 1e-6  # J v against the central difference of f, relative to |J v|
_TOL_VIRIAL = 1e-7  # vᵀ K_σ v of a rigid turn vs the virial of the Warp tangent's forces (its finite differences: 1.5e-8 measured, quadratic)
_TOL_SCALING = 1e-6  # buckling tension ∝ E on uniform fingers (Lanczos tolerance 1e-8)
# The same over the global modes: the tangent's finite-difference round-off (~1e-9) moves them 1.3e-6
# (coarse mesh), their Ritz basis being ill-conditioned (singular values 1 to 1.2e-4).
_TOL_SCALING_GLOBAL = 1e-5
_TOL_EIG = 1e-8  # a Lanczos eigenvalue's relative accuracy (ARPACK tol, mjcodesign.sim.fem.stability)
_POINT_SHARE = 0.01  # mode energy around the tendon's loaded vertices (an indentation would hold most)
_TOL_BUCKLE = 0.15  # chain's buckling tension vs the FEM with the same routing (issue's target)
_TOL_CURL = 0.10  # chain's curl vs the FEM with the same routing, below buckling (issue's target)
_LOG_E = (13.5, 14.2, 14.9, 15.6, 16.3, 17.0)  # uniform fingers, those of tests/test_routing.py


def _fem(log_e=15.0, order=1, **options) -> FemFinger:
    opts = FemOptions(**_COARSE, order=order, routing="printed", **options)
    return FemFinger(FingerDesign(), Stiffness([log_e] * 11), options=opts)


@pytest.fixture(scope="module")
def fem_linear():
    return _fem()


def test_printed_routing_is_refused_where_it_does_not_apply(fem_linear):
    with pytest.raises(DesignError, match="routing"):
        FemOptions(routing="straight")
    with pytest.raises(DesignError, match="frictionless"):
        FemOptions(routing="printed", tendon_law="paper")
    with pytest.raises(DesignError, match="frictionless"):
        fem_linear.tendon_load(1.0, "paper")
    with pytest.raises(DesignError, match="statics only"):
        fem_linear.waypoint_table()  # the explicit tendon kernels' input
    with pytest.raises(DesignError, match="channels"):
        FemFinger(FingerDesign(routing="uniform-height"), Stiffness([15.0] * 11), options=fem_linear.options)


@pytest.mark.parametrize("order", [1, 2])
def test_channel_points_are_embedded_exactly_in_their_segments(order):
    design = FingerDesign()
    mesh = mesh_finger(design, **_COARSE)
    if order == 2:
        mesh = to_quadratic(mesh, design.length)
    points = channel_points(design)
    W, tet = embed_points(mesh, points.reshape(-1, 3))
    np.testing.assert_allclose(W @ mesh.vertices, points.reshape(-1, 3), rtol=0, atol=_TOL_EMBED)
    np.testing.assert_allclose(W.sum(axis=1), 1.0, rtol=0, atol=1e-14)  # a partition of unity
    segments = [b.index for b in design.blocks() if b.kind is BlockKind.SEGMENT]
    np.testing.assert_array_equal(mesh.tet_block[tet], np.repeat(segments, 3))
    with pytest.raises(MeshError, match="outside"):
        embed_points(mesh, [[0.5 * design.length, 0.0, 0.05]])  # 5 cm above the finger


def test_tendon_path_is_anchored_on_the_clamped_base_face(fem_linear):
    fem = fem_linear
    np.testing.assert_allclose(
        fem.tendon_path(fem.mesh.vertices), channel_points(FingerDesign()).reshape(-1, 3), atol=_TOL_EMBED
    )
    x = fem.mesh.vertices.copy()
    free = ~np.isin(np.arange(len(x)), fem.mesh.base)
    x[free] += 1e-3  # everything but the base moves
    np.testing.assert_array_equal(fem.tendon_path(x)[0], channel_points(FingerDesign())[0, 0])


def test_tendon_force_is_minus_tension_times_the_length_gradient(fem_linear):
    # A frictionless tendon of tension T has the potential T ℓ(x), so its load is f = −T ∂ℓ/∂x and
    # its Jacobian ∂f/∂x = −T ∂²ℓ/∂x² (symmetric).
    fem = fem_linear
    rng = np.random.default_rng(0)
    x = fem.mesh.vertices + 1e-4 * rng.standard_normal(fem.mesh.vertices.shape)
    v = rng.standard_normal(x.shape)
    tension, step = 2.0, 1e-6
    f, J = fem.tendon_load(tension)(x)
    dl = (fem.tendon_length(x + step * v) - fem.tendon_length(x - step * v)) / (2 * step)
    assert np.sum(f * v) == pytest.approx(-tension * dl, rel=_TOL_FD_FORCE)
    f_plus, _ = fem.tendon_load(tension)(x + step * v)
    f_minus, _ = fem.tendon_load(tension)(x - step * v)
    Jv = J @ v.ravel()
    np.testing.assert_allclose(
        (f_plus - f_minus).ravel() / (2 * step), Jv, atol=_TOL_FD_JAC * np.abs(Jv).max()
    )


@pytest.mark.parametrize("order", [1, 2])
def test_stress_stiffness_of_a_rigid_turn_is_the_virial_of_the_nodal_forces(order):
    # For a rigid turn v = W X (W skew), ∇v = W, so vᵀ K_σ v = ∫ σ : WᵀW dV = WᵀW : ∫ σ dV, and the
    # discrete divergence theorem gives ∫ σ dV = sym Σ_a f_a ⊗ X_a with f = K₀ u the FEM's own nodal
    # forces (Σ_a X_a ⊗ ∇N_a = I): the stress K_σ builds is the one the Warp tangent carries.
    fem = _fem(order=order)
    X = fem.mesh.vertices
    u = 1e-4 * np.random.default_rng(1).standard_normal(X.shape)
    skew = np.array([[0.0, -1.0, 2.0], [1.0, 0.0, -0.5], [-2.0, 0.5, 0.0]])
    v = (X @ skew.T).ravel()
    forces = (fem.tangent(X) @ u.ravel()).reshape(-1, 3)
    virial = np.einsum("ai,aj->ij", forces, X)
    expected = np.sum(skew.T @ skew * 0.5 * (virial + virial.T))
    assert v @ (fem.stress_stiffness(u) @ v) == pytest.approx(expected, rel=_TOL_VIRIAL)


def test_buckling_tension_scales_with_the_modulus_and_the_follower_alone_never_buckles(fem_linear):
    # Uniform E: every elastic force is ∝ E at fixed ν, so T_crit(E) ∝ E exactly. The follower part
    # alone: λ(G_q C) ≤ 0 (G_q = −∂²ℓ/∂P² is negative semidefinite, the polyline's length being convex
    # in its points; C positive definite), so no tension buckles an unstressed mesh.
    fem = fem_linear
    fem.set_log_e([15.0] * 22)
    a = fem.buckling_tension()
    fem.set_log_e([16.0] * 22)
    b = fem.buckling_tension()
    fem.set_log_e([15.0] * 22)
    assert b.linearised_tension_n / a.linearised_tension_n == pytest.approx(np.e, rel=_TOL_SCALING)
    assert b.global_tension_n / a.global_tension_n == pytest.approx(np.e, rel=_TOL_SCALING_GLOBAL)
    assert a.follower_tension_n == np.inf and a.follower_eigenvalue_per_n < 1e-9
    assert a.mode_block == 1  # the first flexure, as the chain's closed form says (tests/test_routing.py)


def test_global_buckling_bounds_the_linearised_one_and_bends_the_first_flexure(fem_linear):
    # Rayleigh–Ritz: over any subspace S, max_{v∈S} vᵀ(−B)v / vᵀK₀v ≤ μ_max of the whole pencil, so the
    # tension over the global modes (S: responses to the segments' rigid loads) is ≥ the linearised one.
    b = fem_linear.buckling_tension()
    assert b.global_tension_n >= b.linearised_tension_n * (1.0 - _TOL_EIG)
    assert sum(b.mode_block_energy) == pytest.approx(1.0, abs=1e-12)
    assert sum(b.global_mode_block_energy) == pytest.approx(1.0, abs=1e-12)
    assert int(np.argmax(b.global_mode_block_energy)) == 1  # flexure 1, as the chain's closed form
    # The tendon's point forces (all but the tip's are kinks of ~0.015 T) are not where the mode is.
    assert b.mode_energy_at_tendon < _POINT_SHARE


def test_printed_curl_bends_inwards_and_path_stays_stable_well_below_buckling(fem_linear):
    fem = fem_linear
    t_crit = fem.buckling_tension().linearised_tension_n
    path = fem.path_stability([0.01 * t_crit, 0.02 * t_crit])
    assert path.critical_tension_n == np.inf and path.failed_tension_n is None
    assert all(0.0 < e <= 1.0 for e in path.eigenvalues)
    assert 0.0 < path.bend_angles_rad[0] < path.bend_angles_rad[1]
    c = fem.curl(0.02 * t_crit)
    assert c.bend_angle_rad == pytest.approx(path.bend_angles_rad[1], rel=1e-4)  # same equilibrium


# -- the chain against the converged FEM's record -------------------------------------------------------


def _rows(name: str, part: str) -> list:
    """The rows of ``part`` in ``tests/data/fem_routing_{name}.json`` (none when it is not recorded)."""
    path = _DATA / f"fem_routing_{name}.json"
    return json.loads(path.read_text())["record"].get(part, []) if path.exists() else []


def _chain_t_crit(log_e: float) -> float:
    built = build_finger(FingerDesign(), Stiffness([log_e] * 11), FingerModel.CHAIN, options=_PRINTED)
    return buckling_tension(built)[0]


def test_the_buckling_record_is_the_converged_meshs_over_the_case_set():
    rec = json.loads((_DATA / "fem_routing_buckling.json").read_text())
    assert rec["record"]["mesh"] == CONVERGED_MESH and rec["provenance"]["installed"]["commit"]
    assert [r["log_e"] for r in rec["record"]["buckling"]] == list(_LOG_E)


@pytest.mark.xfail(
    strict=True,
    reason="the curls are recorded on the path mesh (quadratic, h 4 mm, 2 spine layers): one converged-mesh "
    "printed curl (random:0 at 0.8 rad) had not finished after 25 min, ~6 CPU-min at a load of 10 on 2 cores",
)
def test_the_curl_record_is_the_converged_meshs_on_ten_designs():
    curls = json.loads((_DATA / "fem_routing_curl.json").read_text())["record"]
    seeds = [int(r["design"].split(":")[1]) for r in curls["curl"]]
    assert not set(seeds) & set(TRAIN_SEEDS)
    assert curls["curl_mesh"] == CONVERGED_MESH and len(seeds) == 10


_LINEAR_MISS = (
    "the converged FEM's linearised buckling tension (initial-stress stiffness) is 0.237x the chain's at every "
    "ln E (0.216 N against 0.914 N at 13.5; uniform E scales both exactly) and not mesh-converged: its mode "
    "is a wrinkle at the foot of segment 0's distal cut (98.5% of its energy within 0.5 mm, 2e-6 around the "
    "tendon's loaded vertices), and it falls as 1.654, 1.260, 0.960 N (ln E 15) as the spine's layers halve "
    "(tests/data/fem_routing_refinement.json); the chain is held to the global modes instead"
)


@pytest.mark.xfail(strict=True, reason=_LINEAR_MISS)
@pytest.mark.parametrize("row", _rows("buckling", "buckling"), ids=lambda r: f"lnE{r['log_e']}")
def test_chain_buckling_tension_matches_the_converged_fem(row):
    # Linear buckling of the unloaded FEM finger: K₀ + T (K_σ − G₀) singular (mjcodesign.sim.fem.stability),
    # against the chain's K + T H singular (mjcodesign.models.stability), both with the printed routing.
    assert _chain_t_crit(row["log_e"]) == pytest.approx(row["fem_linearised_n"], rel=_TOL_BUCKLE)


@pytest.mark.parametrize("row", _rows("buckling", "buckling"), ids=lambda r: f"lnE{r['log_e']}")
def test_uniform_fem_buckling_tension_scales_with_the_modulus(row):
    # Uniform E: T_crit ∝ E for the FEM as for the chain (k ∝ E), so every ln E tests the same ratio;
    # the follower part alone never buckles (mjcodesign.sim.fem.stability).
    assert row["fem_follower_n"] == np.inf
    first = _rows("buckling", "buckling")[0]
    ratio = row["fem_linearised_n"] / first["fem_linearised_n"]
    assert ratio == pytest.approx(np.exp(row["log_e"] - first["log_e"]), rel=_TOL_SCALING)


@pytest.mark.parametrize("row", _rows("curl", "curl"), ids=lambda r: r["design"])
def test_chain_curl_matches_the_converged_fem_below_buckling(row):
    # Free curl (gravity off) at the tension where the chain bends the record's target, far below its
    # buckling tension; bend (sum of hinge angles against the FEM's tip-section rotation) and |tip|.
    assert row["tension_n"] < row["chain_t_crit_n"]
    r = curl(FingerDesign(), Stiffness.parse(row["design"]), "chain", row["tension_n"], options=_PRINTED)
    assert r["bend_angle_rad"] == pytest.approx(row["fem_bend_angle_rad"], rel=_TOL_CURL)
    fem_tip = np.linalg.norm(row["fem_tip_displacement_m"])
    assert np.linalg.norm(r["tip_displacement_m"]) == pytest.approx(fem_tip, rel=_TOL_CURL)


_PATH_MISS = (
    "the FEM's loaded path (path mesh, ln E 13.5; its linearised buckling 0.369 N) stays stable as far as it "
    "was followed: the tangent's smallest eigenvalue (relative to K0) is 4e-6 to 2e-4 > 0 from 0.007 to 0.185 N "
    "while the finger curls 0.15 to 3.6 rad; the run was stopped there, short of the chain's 0.914 N"
)


@pytest.mark.xfail(strict=True, reason=_PATH_MISS)
def test_chain_buckling_tension_matches_the_fem_along_its_loaded_path():
    # Static equilibria at increasing T; the path is unstable where A = K(x) − T G(x) turns singular.
    path = _rows("buckling", "path")
    assert path and path["critical_tension_n"] is not None  # a crossing was found
    assert _chain_t_crit(path["log_e"]) == pytest.approx(path["critical_tension_n"], rel=_TOL_BUCKLE)


# -- the buckling tension as the mesh is refined (tests/data/fem_routing_refinement.json) --------------

_WRINKLE = 0.9  # the linearised mode's energy share at a cut's foot that makes it a local wrinkle
# A buckling tension that moves less than this per halving of the spine's layers counts as converged (the
# calibration's mesh study, CONVERGED_MESH: the tip deflection moved 2.1% then 0.7%).
_TOL_MESH = 0.02
_TOL_CONTINUOUS = 0.15  # the FEM's global mode vs a continuous flexure under the string (the 15%)


def _continuous_flexure_t_crit(k: float, flexure, x_a: float, x_b: float, n: int) -> float:
    """Buckling tension [N] of a flexure of hinge stiffness ``k`` [N·m/rad] as ``n`` equal hinges in series
    under a tendon straight from ``x_a`` to ``x_b`` (:func:`~mjcodesign.models.stability.string_buckling_tension`)."""
    return string_buckling_tension(k, flexure.x0, flexure.x1, x_a, x_b, n)


def test_the_refinement_record_halves_the_spine_layers_then_reaches_the_converged_mesh():
    rec = json.loads((_DATA / "fem_routing_refinement.json").read_text())
    rows = rec["record"]["refinement"]
    assert rec["provenance"]["installed"]["commit"] and rows[-1]["mesh"] == CONVERGED_MESH
    assert [r["mesh"]["spine_layers"] for r in rows[:-1]] == [2, 4, 8]
    assert {r["mesh"]["h"] for r in rows[:-1]} == {4e-3}


def test_linearised_buckling_is_a_wrinkle_at_a_cut_foot_that_refinement_keeps_lowering():
    # A cut's foot is a re-entrant corner (its face meets the spine's top at 102°: 258° of material), whose
    # stress is singular, σ ~ r^(λ−1) with λ sin 2α + sin 2λα = 0, λ = 0.568 (Williams). A wrinkle of size h
    # there costs elastic energy ~E δ² per unit width and releases ~T h^(λ−1) δ², so its tension falls as
    # h^(1−λ) = h^0.43 without bound; the tendon's own point loads are not where the mode is.
    rows = _rows("refinement", "refinement")
    t = [r["fem_linearised_n"] for r in rows[:3]]
    assert t[0] > t[1] > t[2]
    assert min(r["fem_mode_energy_at_feet"] for r in rows[2:]) > _WRINKLE
    for r in rows:
        assert r["fem_mode_energy_at_feet"] > r["fem_global_mode_energy_at_feet"]
        assert r["fem_mode_energy_at_tendon"] < _POINT_SHARE


def test_global_buckling_tension_converges_with_the_mesh():
    # Over the global modes (flexures and segments bending as wholes) the wrinkle is left out.
    rows = _rows("refinement", "refinement")
    t = [r["fem_global_n"] for r in rows]
    assert len(t) == 4 and all(abs(b / a - 1.0) < _TOL_MESH for a, b in zip(t, t[1:], strict=False))
    assert all(int(np.argmax(r["fem_global_mode_block_energy"])) == 1 for r in rows)  # flexure 1


def test_fem_global_buckling_matches_a_continuous_flexure_under_the_tendon():
    # The converged FEM's global mode against flexure 1 as an Euler–Bernoulli beam (the chain's k,
    # calibrated to the converged FEM, times its length), the tendon straight from segment 0's channel exit
    # to segment 1's entry (_continuous_flexure_t_crit): 3.937 N against the FEM's 3.609 N. One hinge at
    # the middle under that string buckles at k (a+b)/(ab), 2.24 N; the chain's guides give its one
    # hinge the beam's tension in the chord's own frame (its slope and height: 4.098 N, test_routing.py).
    row = _rows("refinement", "refinement")[-1]
    built = build_finger(FingerDesign(), Stiffness([row["log_e"]] * 11), FingerModel.CHAIN, options=_PRINTED)
    k = built.model.jnt_stiffness[1]
    flexure = FingerDesign().blocks()[1]
    pts = channel_points(FingerDesign())
    x_a, x_b = pts[0, 2, 0], pts[1, 0, 0]
    a, b = flexure.mid - x_a, x_b - flexure.mid
    assert _continuous_flexure_t_crit(k, flexure, x_a, x_b, 1) == pytest.approx(
        k * (a + b) / (a * b), rel=1e-12
    )
    continuous = _continuous_flexure_t_crit(k, flexure, x_a, x_b, 400)
    assert row["fem_global_n"] == pytest.approx(continuous, rel=_TOL_CONTINUOUS)


@pytest.mark.parametrize("log_e", _LOG_E)
def test_chain_buckling_tension_matches_the_converged_fem_over_its_global_modes(log_e):
    # The converged FEM over its global modes (recorded at ln E 15; a uniform finger's elastic forces are
    # all ∝ E at fixed ν, so T_crit ∝ E exactly: test_buckling_tension_scales_with_the_modulus_and_...)
    # against the chain's K + T H singular: one hinge per flexure between its guides, placed so that it buckles as
    # the flexure bending along its length (tests/test_routing.py), 4.098 N at ln E 15 against the FEM's
    # 3.609 N (+13.5%; the channel ends alone gave 2.354 N, −35%).
    row = _rows("refinement", "refinement")[-1]
    fem = row["fem_global_n"] * np.exp(log_e - row["log_e"])
    assert _chain_t_crit(log_e) == pytest.approx(fem, rel=_TOL_BUCKLE)
