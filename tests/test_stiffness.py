import numpy as np
import pytest

from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, Stiffness
from mjcodesign.errors import StiffnessError


def test_presets():
    assert np.all(Stiffness.preset("soft").log_e == 13.5)
    assert np.all(Stiffness.preset("semi-rigid").log_e == 16.5)
    p = Stiffness.preset("paper-optimized")
    assert p.log_e.shape == (2, 11)
    assert p.log_e[0, 0] == 16.05 and p.log_e[1, -1] == 15.47


def test_eleven_values_mean_both_fingers_alike():
    s = Stiffness(np.linspace(14, 16, 11))
    np.testing.assert_array_equal(s.log_e[0], s.log_e[1])


def test_parse_list_and_preset():
    assert Stiffness.parse("soft") == Stiffness.preset("soft")
    s = Stiffness.parse(",".join(["15"] * 22))
    assert s.young[0, 0] == pytest.approx(np.exp(15))


@pytest.mark.parametrize(
    "values",
    [[15.0] * 10, [15.0] * 23, [float("nan")] + [15.0] * 21, [LOG_E_MIN - 0.1] * 11, [LOG_E_MAX + 0.1] * 11],
)
def test_bad_stiffness_raises(values):
    with pytest.raises(StiffnessError):
        Stiffness(values)


def test_unknown_preset():
    with pytest.raises(StiffnessError):
        Stiffness.parse("rubbery")


def test_parse_random_is_seeded_and_printable():
    s = Stiffness.parse("random:0")
    assert s == Stiffness.random(0) and s != Stiffness.parse("random:1")
    # The tests' random designs: 22 values uniform in the printable range from default_rng(seed).
    np.testing.assert_array_equal(s.log_e.ravel(), np.random.default_rng(0).uniform(LOG_E_MIN, LOG_E_MAX, 22))
    for bad in ("random:", "random:x", "random:-1"):
        with pytest.raises(StiffnessError):
            Stiffness.parse(bad)
