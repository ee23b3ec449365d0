"""The interaction laws as objects: derivatives, closed forms, kernels, registry, scene and files.

What is checked, and the scale every tolerance comes from:

* ``v'`` and ``v''`` against central differences of ``v`` and ``v'``: the
  truncation error is ``s^2 / 6`` times the next derivative, the round-off
  ``eps |f| / s``.  The steepest law is Lennard-Jones at the wall,
  ``|v'''| = 405 w / z0^3`` and ``|v''''| = 4860 w / z0^4``; a step
  ``s = 1e-5`` of the law's length keeps the truncation below ``7e-9 w / L``
  and ``8e-8 w / L^2``, the round-off near ``1e-11`` of those scales
  (Maugis-Dugdale: away from the jump at ``delta``, where ``v`` is linear);
* each law's closed forms: ``v(0) = -w``, ``v -> 0`` far away, ``int_0^G v' =
  v(G) + w``, the largest attraction where the docstring puts it, the process zone
  ``E* w / max v'^2``;
* the compiled kernel (``fill_stress``) against the NumPy ``v'`` and ``v''``
  to a few units in the last place (different operation orders); the
  exponential's own ``exp`` within two units of libm's (each within one of the
  exact value) over the whole range, at its limits, and the same wherever a
  value stands in a row (vectorised or not);
* the registry: one name per law, the scene's kinds the same names, a law
  rebuilt from its file attributes and from a scene equal to itself.
"""
import math

import numpy as np
import pytest

from petgap.io.scene import ADHESIVE_LAWS, Scene
from petgap.mechanics import interactions
from petgap.mechanics.interactions import (LAWS, ExponentialAdhesion, HardWall,
                                           LennardJones93Adhesion, MaugisDugdaleAdhesion,
                                           SquaredExponentialAdhesion, from_attributes,
                                           from_scene, law_class, resolution_report)

W, LENGTH = 0.3, 0.7
ADHESIVE = [ExponentialAdhesion(W, LENGTH), MaugisDugdaleAdhesion(W, LENGTH),
            LennardJones93Adhesion(W, LENGTH), SquaredExponentialAdhesion(W, LENGTH)]
IDS = [law.name for law in ADHESIVE]


def gaps(law):
    """Gaps over ten length scales, away from the Maugis-Dugdale jump at ``delta``."""
    g = np.linspace(0.0, 10.0 * LENGTH, 401)
    return g[np.abs(g - law.range) > 1e-3 * LENGTH]


@pytest.mark.parametrize("law", ADHESIVE, ids=IDS)
def test_derivatives_match_central_differences(law):
    g = gaps(law)
    s = 1e-5 * LENGTH
    inner = g[g >= s]  # one-sided at the wall is not a central difference
    dv = (law.energy(inner + s) - law.energy(inner - s)) / (2 * s)
    ddv = (law.derivative(inner + s) - law.derivative(inner - s)) / (2 * s)
    scale = W / LENGTH
    np.testing.assert_allclose(dv, law.derivative(inner), rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(ddv, law.curvature(inner), rtol=0, atol=1e-7 * scale / LENGTH)


@pytest.mark.parametrize("law", ADHESIVE, ids=IDS)
def test_closed_forms(law):
    """``v(0) = -w``, ``v(inf) = 0``, ``int v' = w``, the largest attraction, the process zone."""
    g = np.linspace(0.0, 400.0 * LENGTH, 4_000_001)
    vp = law.derivative(g)
    assert float(law.energy(np.zeros(1))[0]) == pytest.approx(-W, rel=1e-15)
    assert abs(float(law.energy(np.array([1e4 * LENGTH]))[0])) < 1e-10 * W
    assert np.all(vp >= 0)  # attraction only
    integral = float(np.sum(0.5 * (vp[1:] + vp[:-1]) * np.diff(g)))
    # the trapezoids: off by (dg^2 / 12) |v''(0)| <= 2.3e-8 w (Euler-Maclaurin; Lennard-Jones,
    # v''(0) = 27 w / z0^2), and by up to dg max v' / 2 = 5e-5 w across the jump of v'
    tail = float(law.energy(g[-1:])[0])  # the Lennard-Jones tail beyond: -(3 w / 2) s^3
    assert integral == pytest.approx(W + tail, rel=1e-4 if law.name == "maugis-dugdale" else 1e-7)
    assert float(vp.max()) == pytest.approx(law.max_attraction, rel=1e-6)
    assert law.process_zone(2.5) == pytest.approx(2.5 * W / law.max_attraction ** 2, rel=1e-14)
    assert law.length_scale == LENGTH and law.adhesive and law.work == W


def test_each_law_where_its_docstring_says():
    """Where the attraction peaks and what ``v'(0)``, ``v''(0)`` are, per law."""
    exp, md, lj, se = ADHESIVE
    assert exp.max_attraction == W / LENGTH and exp.curvature_from_stress == LENGTH
    assert float(exp.derivative(0.0)) == W / LENGTH
    assert md.max_attraction == W / LENGTH and md.curvature_from_stress == math.inf
    assert float(md.derivative(LENGTH * (1 - 1e-12))) == W / LENGTH
    assert float(md.derivative(LENGTH)) == 0.0 and float(md.energy(LENGTH)) == 0.0
    peak = LENGTH * ((5 / 2) ** (1 / 6) - 1)  # s^6 = 2/5
    assert float(lj.derivative(peak)) == pytest.approx(lj.max_attraction, rel=1e-14)
    assert float(lj.curvature(peak)) == pytest.approx(0.0, abs=1e-12 * W / LENGTH ** 2)
    assert float(lj.derivative(0.0)) == 0.0
    assert float(lj.curvature(0.0)) == pytest.approx(27 * W / LENGTH ** 2, rel=1e-14)
    assert lj.max_attraction == pytest.approx(1.4658 * W / LENGTH, rel=1e-4)
    assert float(se.derivative(LENGTH)) == pytest.approx(se.max_attraction, rel=1e-14)
    assert float(se.curvature(LENGTH)) == pytest.approx(0.0, abs=1e-15)
    assert float(se.derivative(0.0)) == 0.0 and float(se.curvature(0.0)) == W / LENGTH ** 2
    assert se.process_zone(1.0) == pytest.approx(math.e * LENGTH ** 2 / W, rel=1e-14)


@pytest.mark.parametrize("law", ADHESIVE, ids=IDS)
def test_compiled_kernel_is_the_law(law):
    g = np.ascontiguousarray(gaps(law)[:400].reshape(20, 20))
    vp, vpp = np.empty_like(g), np.empty_like(g)
    second = law.curvature_from_stress is None
    law.fill_stress(g, vp, vpp if second else None)
    np.testing.assert_allclose(vp, law.derivative(g), rtol=4e-16 * 8, atol=1e-300)
    if second:
        np.testing.assert_allclose(vpp, law.curvature(g), rtol=0,
                                   atol=1e-14 * W / LENGTH ** 2)
    else:  # the gap solver takes v'' = -v' / L
        np.testing.assert_allclose(-vp / law.curvature_from_stress, law.curvature(g), rtol=1e-15,
                                   atol=0)


def test_exponential_kernel_is_exp_within_an_ulp_wherever_it_stands():
    law = ExponentialAdhesion(1.0, 1.0)   # vp = exp(-g) exactly as the kernel forms it
    rng = np.random.default_rng(7)
    g = np.concatenate([np.linspace(0.0, 708.0, 7081), rng.exponential(5.0, 4000),
                        rng.uniform(0.0, 0.35, 1000), [0.0, 1e-300, 0.5 * math.log(2)]])
    vp = np.empty((1, g.size))
    law.fill_stress(g.reshape(1, -1), vp)
    libm = np.array([math.exp(-x) for x in g])
    assert np.all(np.abs(vp[0] - libm) <= 2 * np.spacing(libm))
    limits = np.array([[0.0, 708.5, 800.0, np.inf, np.nan, -800.0]])
    out = np.empty_like(limits)
    law.fill_stress(limits, out)
    assert out[0, 0] == 1.0 and out[0, 1] == 0.0 and out[0, 2] == 0.0 and out[0, 3] == 0.0
    assert np.isnan(out[0, 4]) and out[0, 5] == np.inf
    # the same values at every alignment and in rows of other lengths: no lane or
    # remainder of a vectorised loop gives a value of its own
    row = rng.exponential(6.0, 203)
    first = None
    for offset in range(8):
        for length in (203, 197, 5):
            buffer, result = np.zeros(220), np.zeros(220)
            buffer[offset:offset + 203] = row
            law.fill_stress(buffer[offset:offset + length].reshape(1, -1),
                            result[offset + 3:offset + 3 + length].reshape(1, -1))
            values = result[offset + 3:offset + 3 + min(length, 5)]
            first = values.copy() if first is None else first
            assert np.array_equal(values, first)


def test_hard_wall_is_no_interaction():
    wall = HardWall()
    g = np.linspace(0, 3, 7)
    assert not wall.adhesive and wall.length_scale == 0.0 and wall.max_attraction == 0.0
    for f in (wall.energy, wall.derivative, wall.curvature):
        assert np.all(f(g) == 0.0)
    assert resolution_report(wall, 1.0, 1.0)["resolved"]


@pytest.mark.parametrize("law", ADHESIVE, ids=IDS)
def test_invalid_parameters_are_named(law):
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match=f"{type(law).__name__} work must be positive"):
            type(law)(bad, LENGTH)
        with pytest.raises(ValueError, match=f"{type(law).__name__} range must be positive"):
            type(law)(W, bad)


def test_registry_names_every_law_once_and_the_scene_knows_them():
    assert list(LAWS) == ["hard-wall", *ADHESIVE_LAWS]
    assert all(cls.name == name for name, cls in LAWS.items())
    assert {type(law) for law in ADHESIVE} | {HardWall} == set(LAWS.values())
    assert law_class("maugis-dugdale") is MaugisDugdaleAdhesion
    with pytest.raises(ValueError, match="interaction.kind = 'dugdale' is not known; allowed: "
                                         "hard-wall, exponential, maugis-dugdale"):
        law_class("dugdale")
    assert set(interactions.__all__) >= {"LAWS", "from_scene", "from_attributes"}


@pytest.mark.parametrize("law", ADHESIVE + [HardWall()], ids=IDS + ["hard-wall"])
def test_file_attributes_both_ways(law):
    attrs = law.attributes()
    assert attrs["kind"] == law.name
    assert from_attributes(attrs["kind"], attrs.get) == law


@pytest.mark.parametrize("law", ADHESIVE, ids=IDS)
def test_scene_makes_the_law(comm, law):
    scene = Scene.from_dict({"grid": {"nx": 8}, "surface": {"kind": "paraboloid", "radius": 4},
                             "interaction": {"kind": law.name, "work_of_adhesion": W,
                                             "range": LENGTH}}, comm)
    assert from_scene(scene.interaction) == law


def test_resolution_messages_name_each_laws_length(comm):
    """The range in pixels and the process zone, in each law's own symbols."""
    texts = {"exponential": ("range rho = 0.7", "process zone E* rho^2 / w"),
             "maugis-dugdale": ("range delta = 0.7", "process zone E* delta^2 / w"),
             "lennard-jones-9-3": ("range z0 = 0.7", "process zone E* w / sigma0^2"),
             "squared-exponential": ("range rho = 0.7", "process zone e E* rho^2 / w")}
    for law in ADHESIVE:
        report = resolution_report(law, 1.0, 1e-3)
        assert not report["resolved"]
        for text in texts[law.name]:
            assert text in report["message"]
        assert report["process_zone"] == pytest.approx(law.process_zone(1e-3), rel=1e-15)
        assert resolution_report(law, 0.01, 10.0)["resolved"]
