"""Prop. 4.2 and Condition 4.1 (thesis §4.3.2.3) against the published parameters.

§4.5: A = diag(5, 8.57, 12), u = [0, 0.6455, 0.7638], Δ* = 5, γ = 1.9251,
Ξ = {0.08π}, δ = 0.0030.  §5.6: the same A, u, γ with Ξ = {0.9π}, δ = 0.3848.
Published numbers are printed to 4 decimals, hence the 5e-5 tolerances.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from zswarm.families import synergistic as hybrid
from zswarm.math import so3

A45 = np.diag([5.0, 8.57, 12.0])
U45 = np.array([0.0, 0.6455, 0.7638])


def test_design_reproduces_section_4_5():
    d = hybrid.design(A45, [0.08 * math.pi])
    assert d.case == 2
    assert np.allclose(d.u, U45, atol=5e-5)
    assert d.Delta_star == pytest.approx(5.0)
    assert d.gamma == pytest.approx(1.9251, abs=5e-5)  # 95 % of 4Δ*/π² = 2.0264
    assert d.delta == pytest.approx(0.0030, abs=5e-5)
    assert d.condition_holds


def test_design_reproduces_section_5_6():
    d = hybrid.design(A45, [0.9 * math.pi])
    assert d.gamma == pytest.approx(1.9251, abs=5e-5)
    assert d.delta == pytest.approx(0.3848, abs=5e-5)
    assert d.condition_holds


@pytest.mark.parametrize("xi, delta", [(0.08 * math.pi, 0.0030), (0.9 * math.pi, 0.3848)])
def test_published_parameters_pass_the_check(xi, delta):
    d = hybrid.check_parameters(A45, U45, 1.9251, delta, [xi])
    assert d.delta < d.delta_max and d.gamma < d.gamma_max
    assert min(d.gaps) > delta


@pytest.mark.parametrize("eps", [1e-2, 3e-3])
def test_case_three_meets_case_two_continuously(eps):
    """At λ2 = b = λ1λ3/(λ3−λ1) the third case's α² and Δ* equal the second's, and below b they
    leave it at the rates the formulas give: with D = λ1λ2 + λ1λ3 + λ2λ3, case 3's
    Δ* = 2λ1λ2λ3/D and α_i² = 1 − 2Π_{l≠i}λ_l/D have, at λ2 = b (where D = 2λ1λ3²/(λ3−λ1)),
    dΔ*/dλ2 = (λ3−λ1)²/(2λ3²), dα1²/dλ2 = −(λ3−λ1)²/(2λ1λ3²), dα2²/dλ2 = (λ1+λ3)(λ3−λ1)²/(2λ1λ3³),
    dα3²/dλ2 = −(λ3−λ1)²/(2λ3³).  So at λ2 = b(1 − ε) each gap is −(derivative)·εb to first
    order; the second-order term is |f''/(2f')|·εb of it: for Δ*, f'' = −(λ1+λ3)(λ3−λ1)³/(2λ1λ3⁴),
    0.71ε here (measured the same, 0.66-0.73ε, for the α_i²), so each gap is within ε of its
    first-order value, relatively.  (α itself, a square root, leaves 0 like sqrt(ε): compared
    on α².)"""
    l1, l3 = 5.0, 12.0
    b = l1 * l3 / (l3 - l1)
    d2 = hybrid.design(np.diag([l1, b, l3]), [1.0])
    d3 = hybrid.design(np.diag([l1, b * (1 - eps), l3]), [1.0])
    assert (d2.case, d3.case) == (2, 3)
    h = -eps * b  # the change of λ2
    slopes = {
        "Delta*": (d3.Delta_star - d2.Delta_star, (l3 - l1) ** 2 / (2 * l3**2)),
        "alpha1^2": (d3.alpha[0] ** 2 - d2.alpha[0] ** 2, -((l3 - l1) ** 2) / (2 * l1 * l3**2)),
        "alpha2^2": (d3.alpha[1] ** 2 - d2.alpha[1] ** 2, (l1 + l3) * (l3 - l1) ** 2 / (2 * l1 * l3**3)),
        "alpha3^2": (d3.alpha[2] ** 2 - d2.alpha[2] ** 2, -((l3 - l1) ** 2) / (2 * l3**3)),
    }
    for name, (gap, slope) in slopes.items():
        assert gap == pytest.approx(slope * h, rel=eps), (name, gap, slope * h)


@pytest.mark.parametrize(
    "kw, field",
    [
        (dict(gamma=2.1), "gamma"),
        (dict(delta=0.01), "delta"),
        (dict(gamma=-1.0), "gamma"),
    ],
)
def test_bounds_that_fail_are_named(kw, field):
    with pytest.raises(hybrid.DesignError) as exc:
        hybrid.design(A45, [0.08 * math.pi], **kw)
    assert exc.value.field == field


def test_wrong_u_and_bad_A_are_rejected():
    with pytest.raises(hybrid.DesignError, match="not Prop. 4.2's u"):
        hybrid.check_parameters(A45, np.array([1.0, 0, 0]), 1.9251, 0.003, [0.08 * math.pi])
    with pytest.raises(hybrid.DesignError, match="distinct"):
        hybrid.check_parameters(np.diag([5.0, 5.0, 12.0]), U45, 1.0, 0.001, [0.5])
    with pytest.raises(hybrid.DesignError, match="positive definite"):
        hybrid.check_A(np.diag([-1.0, 2.0, 3.0]))
    with pytest.raises(hybrid.DesignError, match=r"\(0, π\]"):
        hybrid.design(A45, [4.0])


@settings(max_examples=examples(60), deadline=None)
@given(
    lam=st.tuples(*[st.floats(0.5, 20.0)] * 3).filter(lambda t: len({round(x, 2) for x in t}) == 3),
    xi=st.floats(0.05, math.pi),
)
def test_prop_4_2_implies_condition_4_1(lam, xi):
    """Whatever A (distinct eigenvalues) and ξ: the designed parameters satisfy Condition 4.1."""
    d = hybrid.design(np.diag(sorted(lam)), [xi])
    assert d.condition_holds, d.as_dict()


def test_gradients_match_finite_differences():
    """Prop. 4.1: ∇_ξ U exactly; d/dε U(R̄ exp(ε[x]^x), ξ) = 2 x^T Ra(ξ,u) ψ(A R̄ Ra(ξ,u)). Central differences, h = 1e-6: error ~1e-9."""
    rng = np.random.default_rng(3)
    u = U45 / np.linalg.norm(U45)  # Prop. 4.1 holds for a unit u
    for _ in range(20):
        R, xi, x, h = so3.exp(rng.normal(size=3)), rng.normal(), rng.normal(size=3), 1e-6
        dxi = (hybrid.potential(A45, u, 1.9, R, xi + h) - hybrid.potential(A45, u, 1.9, R, xi - h)) / (2 * h)
        dR = (hybrid.potential(A45, u, 1.9, R @ so3.exp(h * x), xi) - hybrid.potential(A45, u, 1.9, R @ so3.exp(-h * x), xi)) / (2 * h)
        assert dxi == pytest.approx(hybrid.grad_xi(A45, u, 1.9, R, xi), abs=1e-6)
        assert dR == pytest.approx(2 * x @ hybrid.grad_R(A45, u, R, xi), abs=1e-6)


def test_undesired_critical_points_are_critical():
    """Prop. 4.1: at ξ = 0 and R̄ = Ra(π, q_β) both gradients vanish (ψ(A R̄) = 0)."""
    for b in range(3):
        R_bar = so3.Ra(math.pi, np.eye(3)[b])
        assert np.allclose(hybrid.grad_R(A45, U45, R_bar, 0.0), 0, atol=1e-12)
        assert hybrid.grad_xi(A45, U45, 1.9251, R_bar, 0.0) == pytest.approx(0, abs=1e-12)
