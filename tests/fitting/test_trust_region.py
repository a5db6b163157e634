"""The trust-region subproblems of the Gauss-Newton step (``fitting.trust_region``): on a
hyperplane (the stiffness wall's), and within bounds and a half-space."""

import numpy as np
import pytest

from hframe_id.fitting.trust_region import bounded_step, step_on_hyperplane, trust_region_step


def test_the_step_on_a_hyperplane_is_the_minimiser_on_its_hyperplane():
    """min |d - (1, 0)|^2 / 2 on d1 + d2 = 0: d = (1/2, -1/2) (the projection of the
    unconstrained minimiser onto the hyperplane), inside a region it does not reach."""
    h = np.eye(2)
    g = np.array([-1.0, 0.0])
    d, whole = step_on_hyperplane(h, g, np.array([1.0, 1.0]), 0.0, radius=10.0)
    np.testing.assert_allclose(d, [0.5, -0.5], atol=1e-12)
    assert whole


def test_the_step_on_a_hyperplane_meets_the_margin_and_the_region():
    """A curved model, a wall at margin 0.3 along n = (2, -1, 0): the step ends on it
    (n . d = 0.3), is no longer than the region, and no point of the hyperplane within the
    region has a lower model value (checked on 2,000 seeded draws)."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=(3, 3))
    h = a @ a.T + 0.1 * np.eye(3)
    g = np.array([-3.0, 2.0, 1.0])
    normal = np.array([2.0, -1.0, 0.0])
    radius = 0.8
    d, _ = step_on_hyperplane(h, g, normal, 0.3, radius)
    assert normal @ d == pytest.approx(0.3, abs=1e-12)
    assert np.linalg.norm(d) <= radius * (1 + 1e-9)

    def model(x):
        return g @ x + 0.5 * x @ h @ x

    n = normal / np.linalg.norm(normal)
    d0 = n * 0.3 / np.linalg.norm(normal)
    basis = np.linalg.svd(n[None, :])[2][1:]
    # Draws on the hyperplane inside the region; the bisection that sizes the region's
    # step stops at 1e-6 relative, so the step may be beaten by that much, no more.
    z = rng.normal(size=(2000, 2)) * 0.5
    points = d0 + z @ basis
    inside = points[np.linalg.norm(points, axis=1) <= radius]
    assert len(inside) > 100
    assert model(d) <= min(model(x) for x in inside) + 1e-6 * abs(model(d))


def test_a_hyperplane_beyond_the_region_gives_the_step_towards_it():
    """The hyperplane farther than the region: the step goes straight to it, cut at the
    region's edge."""
    # the hyperplane d2 = 2
    d, whole = step_on_hyperplane(np.eye(2), np.array([1.0, 1.0]), np.array([0.0, 3.0]), 6.0, 0.5)
    np.testing.assert_allclose(d, [0.0, 0.5])
    assert not whole


def test_a_step_that_stays_inside_the_half_space_is_the_free_step():
    h, g = np.eye(2), np.array([-0.1, 0.05])
    d, whole = bounded_step(
        h,
        g,
        np.zeros(2),
        -np.ones(2),
        np.ones(2),
        1.0,
        np.ones(2, bool),
        (np.array([1.0, -1.0]), 0.2),
    )
    np.testing.assert_allclose(d, trust_region_step(h, g, 1.0)[0], atol=0)
    assert whole


@pytest.mark.parametrize("held_by", ["bound", "not movable"])
def test_a_held_parameter_does_not_push_the_step_off_the_half_spaces_plane(held_by):
    """min |d - (1, 1, -1)|^2 / 2 with d1 + d3 <= 0.5 and parameter 3 held (at its lower
    bound with its step pointing down, or not movable): the step on the two that move meets
    the plane, d = (0.5, 1, 0). Solved on all three and then clipped (the solver before),
    it was (1.25, 1, -0.75), clipped into the box (1, 1, 0): n . d = 1, beyond the plane."""
    g = np.array([-1.0, -1.0, 1.0])
    theta = np.array([0.0, 0.0, -1.0 if held_by == "bound" else 0.0])
    movable = np.array([True, True, held_by == "bound"])
    d, _ = bounded_step(
        np.eye(3),
        g,
        theta,
        -np.ones(3),
        np.ones(3),
        10.0,
        movable,
        (np.array([1.0, 0.0, 1.0]), 0.5),
    )
    np.testing.assert_allclose(d, [0.5, 1.0, 0.0], atol=1e-12)
