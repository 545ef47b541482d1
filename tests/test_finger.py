import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign, Routing
from mjcodesign.errors import DesignError

# The printed finger's envelope (STL) is 20 x 14 x 136.35 mm; trimesh reads it exactly.
_TOL_ENVELOPE_M = 1e-4
# Our blocks are plain prisms; the printed finger has fillets and a tendon channel.
_TOL_VOLUME_REL = 0.15


def test_default_is_the_papers_finger():
    d = FingerDesign()
    assert d.n_blocks == 11
    kinds = [b.kind for b in d.blocks()]
    assert kinds.count(BlockKind.SEGMENT) == 6 and kinds.count(BlockKind.FLEXURE) == 5
    assert d.flexure_thickness == pytest.approx(0.002)
    assert d.envelope == pytest.approx((0.020, 0.014, 0.13635))
    blocks = d.blocks()
    assert blocks[0].x0 == 0 and blocks[-1].x1 == pytest.approx(d.length)
    for a, b in zip(blocks[:-1], blocks[1:], strict=True):
        assert a.x1 == pytest.approx(b.x0)


def test_uniform_pressure_waypoints_follow_the_law():
    d = FingerDesign()
    mids = np.array([b.mid for b in d.blocks()])
    # h_i = H (1 - l_i / L)^2 above the flexures' neutral plane
    expected = d.tendon_height * (1 - mids / d.length) ** 2
    np.testing.assert_allclose(d.waypoint_heights(), expected, rtol=1e-12)
    np.testing.assert_allclose(d.waypoints()[:, 2], expected + 0.5 * d.flexure_thickness)
    assert np.all(np.diff(d.waypoint_heights()) < 0)


def test_uniform_height_routing_is_kept():
    d = FingerDesign(routing="uniform-height")
    assert d.routing is Routing.UNIFORM_HEIGHT
    assert np.ptp(d.waypoint_heights()) == 0


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(length=-1.0),
        dict(width=float("nan")),
        dict(n_segments=1),
        dict(tendon_height=0.05),
        dict(flexure_thickness=0.01),
        dict(routing="spiral"),
        dict(flexure_length=0.05),
    ],
)
def test_bad_designs_raise(kwargs):
    with pytest.raises(DesignError):
        FingerDesign(**kwargs)


def test_block_count_and_sizes_are_parameters():
    d = FingerDesign(n_segments=4, length=0.1, flexure_length=0.006)
    assert d.n_blocks == 7
    assert sum(b.length for b in d.blocks()) == pytest.approx(0.1)


def test_envelope_matches_printed_finger(reference_dir):
    trimesh = pytest.importorskip("trimesh")
    stl = trimesh.load(reference_dir / "hardware" / "sim_finger.stl")
    ext_mm = np.sort(stl.extents)  # STL is in millimetres
    d = FingerDesign()
    ours = np.sort(np.array(d.envelope))
    np.testing.assert_allclose(ours, ext_mm / 1000.0, atol=_TOL_ENVELOPE_M)
    vol_ref = stl.volume * 1e-9
    vol = sum(b.volume for b in d.blocks())
    assert abs(vol - vol_ref) / vol_ref < _TOL_VOLUME_REL
