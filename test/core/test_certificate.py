"""The certificate of matching (core/certificate.py) against the paper's claims.

Thm 4.2, Props 2.1 (ii), 2.2 (ii)   first order, complete graph, D0 < 1: the certified bound on
                                    the matching diameter holds on integrated trajectories, and
                                    the ensemble is matched no later than the certified time
2-D half-circle (Kuramoto)          the same on connected undirected graphs
Prop. 2.1 (i), 2.2 (i)              second order: not certified, the centroids' rate reported
"""

import math

import numpy as np
import pytest
from core_testlib import (
    brute_matching_diameter,
    brute_rotation_diameter,
    make_scene,
    rot_matrices,
)
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

from polymatch_ros.core import load_scene, simulate
from polymatch_ros.core.certificate import (
    Certificate,
    CertificateKeeper,
    HalfCircleBound,
    LoheBound,
    ceil_significant,
    certify,
)
from polymatch_ros.core.model import State

# no shrinking: a failing example is printed as drawn (shrinking re-integrates for minutes)
PROPERTY = settings(max_examples=10, deadline=None, derandomize=True,
                    phases=[Phase.explicit, Phase.generate],
                    suppress_health_check=[HealthCheck.too_slow])


def _check_against_trajectory(scene, cert, steps_per_unit):
    """Integrate up to the certified time (on a step grid that lands on it): the bound holds at
    every sample (within the integrator's error), and the diameter is below tolerance there."""
    assert cert.certified and cert.time is not None
    rate = max(b.rate for b in cert.bounds)
    n = 40 * math.ceil(cert.time * max(rate, 1e-3) * steps_per_unit / 40)
    samples = np.linspace(0.0, cert.time, 41)
    traj = simulate(load_scene_with_end(scene, cert.time), "rkmk4", cert.time / n,
                    samples=samples)
    times = np.array(traj.times)
    np.testing.assert_allclose(times, samples, rtol=1e-12)
    observed = np.array([brute_matching_diameter(traj.scene.model, s, 0) for s in traj.states])
    bound = np.asarray(cert.bound(times))
    assert np.all(observed <= bound * (1 + 1e-6) + 1e-14), \
        f"bound violated: max ratio {np.max(observed / bound)}"
    assert observed[-1] < scene.tolerance * (1 + 1e-6)
    below = np.flatnonzero(observed >= scene.tolerance)
    first_matched = times[below[-1] + 1] if len(below) else times[0]
    assert first_matched <= cert.time                 # observed no later than certified
    return observed, bound


def load_scene_with_end(scene, t_end):
    """The same scene (same initial state) with another t_end."""
    from dataclasses import replace
    return replace(scene, t_end=t_end, samples=np.array([0.0, t_end]))


@PROPERTY
@given(dim=st.sampled_from([2, 3, 4]), count=st.integers(2, 6), seed=st.integers(0, 10_000),
       within=st.floats(0.02, 0.45), kappa=st.floats(0.5, 3.0), gamma=st.floats(0.5, 4.0),
       box=st.floats(0.0, 3.0))
def test_certified_bound_holds_and_time_is_kept_thm_4_2_prop_2_2(dim, count, seed, within,
                                                               kappa, gamma, box):
    scene = make_scene(dim, 1, count=count, seed=seed, kappa=kappa, gamma=gamma,
                       rotations={"within": within}, centroids={"box": [-box - 1e-3, box]})
    cert = certify(scene.model, scene.initial, scene.tolerance)
    d0 = brute_rotation_diameter(rot_matrices(scene.model.rotations, scene.initial.groups[0].rot))
    assume(d0 < 1.0)                                   # the hypothesis of Theorem 4.2
    assert isinstance(cert.bounds[0], LoheBound) and cert.bounds[0].rotations == \
        pytest.approx(d0, rel=1e-12)
    assert cert.bounds[0].rate == pytest.approx(kappa / gamma)   # (A-2)'s time scale
    assert cert.centroid_rate == pytest.approx(kappa / gamma)
    assert cert.line().startswith(f"certified: matching diameter < {scene.tolerance:g} by t <= ")
    _check_against_trajectory(scene, cert, steps_per_unit=12)


@PROPERTY
@given(count=st.integers(3, 6), seed=st.integers(0, 10_000), within=st.floats(0.1, 1.4),
       graph=st.sampled_from(["complete", {"ring": 1}, {"ring": 1, "normalise": "degree"},
                              {"k_nearest": 2}]),
       kappa=st.floats(0.5, 3.0), gamma=st.floats(0.5, 2.0))
def test_half_circle_certificate_holds_on_connected_graphs_2d(count, seed, within, graph,
                                                             kappa, gamma):
    data = _scene_data(2, count, seed, kappa, gamma, {"within": within})
    data["graph"] = graph
    scene = load_scene(data)
    cert = certify(scene.model, scene.initial, scene.tolerance)
    if not isinstance(cert.bounds[0] if cert.bounds else None, HalfCircleBound):
        assert graph == "complete" and cert.certified     # D0 < 1: Theorem 4.2 took it
        return
    assert cert.certified and "half-circle" in cert.theorem
    _check_against_trajectory(scene, cert, steps_per_unit=8)


def _scene_data(dim, count, seed, kappa, gamma, rotations, order=1):
    model = {"order": order, "kappa": kappa, "gamma": gamma}
    if order == 2:
        model["mass"] = 0.5
    return {"dimension": dim, "seed": seed, "model": model, "time": {"t_end": 1.0},
            "groups": [{"name": "g", "shape": {"simplex": dim}, "count": count,
                        "rotations": rotations, "centroids": {"box": [-2.0, 2.0]}}]}


@pytest.mark.parametrize("d0,line_time", [(0.5, "27.0"), (0.95, "32.9")])
def test_two_tetrahedra_certified_time_closed_form_thm_4_2(d0, line_time):
    """Two polytopes with one centroid, rotated by phi about one axis, D0 = 2 sqrt 2 sin(phi/2),
    R = 1, c = kappa/gamma = 0.5: the bound R/sqrt 2 D0 e^{-c t}/(1 - D0 + D0 e^{-c t})
    reaches 1e-6 at e^{c t} = (D0 / (sqrt 2 1e-6) - D0) / (1 - D0) (t = 2 ln(1e6/sqrt 2 - 1) =
    26.938 for D0 = 0.5); the exact flow (N = 2: phi' = -c sin phi, tan(phi/2) =
    tan(phi0/2) e^{-c t}) stays below the bound and is what the integrator follows."""
    phi = 2 * math.asin(d0 / (2 * math.sqrt(2)))
    vecs = [[0.0, 0.0, phi / 2], [0.0, 0.0, -phi / 2]]
    data = {"dimension": 3, "model": {"order": 1, "kappa": 2.0, "gamma": 4.0},
            "time": {"t_end": 30.0}, "convergence": {"tolerance": 1e-6},
            "groups": [{"name": "g", "shape": "tetrahedron", "count": 2,
                        "centroids": {"points": [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]},
                        "rotations": {"rotvecs": vecs}}]}
    scene = load_scene(data)
    cert = certify(scene.model, scene.initial, scene.tolerance)
    expected = 2 * math.log((d0 / (math.sqrt(2) * 1e-6) - d0) / (1 - d0))
    if d0 == 0.5:
        assert expected == pytest.approx(26.938, abs=1e-3)
    assert cert.time == pytest.approx(expected, rel=1e-9)
    assert cert.line() == (f"certified: matching diameter < 1e-06 by t <= {line_time} "
                           "(Thm 4.2, Props 2.1 (ii), 2.2 (ii))")
    t = np.linspace(0.0, 40.0, 81)
    exact_phi = 2 * np.arctan(np.tan(phi / 2) * np.exp(-0.5 * t))
    ref = scene.model.groups[0].reference
    lever = np.max(np.linalg.norm(ref[:, :2], axis=1))   # distance from the rotation axis
    exact = 2 * np.sin(exact_phi / 2) * lever
    assert np.all(exact <= cert.bound(t) * (1 + 1e-12))
    traj = simulate(load_scene_with_end(scene, 40.0), "rkmk4", 0.1, samples=t)
    seen = np.array([brute_matching_diameter(traj.scene.model, s, 0) for s in traj.states])
    np.testing.assert_allclose(seen, exact, rtol=1e-6, atol=1e-13)


def test_not_certified_with_the_reason_prop_2_1_prop_2_2():
    def line(data):
        scene = load_scene(data)
        return certify(scene.model, scene.initial, scene.tolerance)

    second = line(_scene_data(3, 4, 1, 1.0, 1.0, {"within": 0.1}, order=2))
    # m = 0.5, gamma = kappa = 1: gamma^2 < 4 m kappa, so the rate is gamma/(2m) = 1
    assert not second.certified and second.centroid_rate == pytest.approx(1.0)
    assert second.line() == ("not certified: second-order model: the paper gives no rotation "
                             "bound (Prop. 2.2 (i) has no rate); centroids contract at rate 1 "
                             "(Prop. 2.1 (i))")
    far = line(_scene_data(3, 4, 1, 1.0, 1.0, "uniform"))
    assert far.line().startswith("not certified: D0 = ") and far.line().endswith(
        " >= 1 (Thm 4.2 needs max |O_i - O_j|_F < 1)")
    spread = line(_scene_data(2, 3, 1, 1.0, 1.0, {"angles": [0.0, 2.2, 4.4]}))
    assert spread.line() == ("not certified: D0 = 2.52 >= 1 (Thm 4.2 needs max |O_i - O_j|_F "
                             "< 1); phases spread over 4.08 >= pi (not within an open "
                             "half-circle)")
    similar = _scene_data(3, 4, 1, 1.0, 1.0, {"within": 0.1})
    similar["groups"][0]["scales"] = [1.0, 1.5, 2.0, 2.5]
    assert line(similar).reason == "similar polytopes (F-1): the paper proves nothing for them"
    graph3 = _scene_data(3, 4, 1, 1.0, 1.0, {"within": 0.1})
    graph3["graph"] = {"ring": 1}
    assert line(graph3).reason == "graph in d = 3: no result is cited (only for 2-D)"
    directed = _scene_data(2, 3, 1, 1.0, 1.0, {"within": 0.1})
    directed["graph"] = {"edges": [[0, 1], [1, 2], [2, 0]], "directed": True}
    assert line(directed).reason == "directed graph: no result is cited for it"
    apart = _scene_data(2, 4, 1, 1.0, 1.0, {"within": 0.1})
    apart["graph"] = {"edges": [[0, 1], [2, 3]], "allow_disconnected": True}
    assert line(apart).reason == "disconnected graph: its components need not match"
    radio = _scene_data(2, 4, 1, 1.0, 1.0, {"within": 0.1})
    radio["graph"] = {"radius": 50.0}
    assert line(radio).reason.startswith("proximity graph: its edges change with the state")
    mixed = _scene_data(2, 3, 1, 1.0, 1.0, {"within": 0.1})
    mixed["model"].update(kappa_2=1.0, L=2.0)
    mixed["groups"].append(dict(mixed["groups"][0], name="h"))
    assert line(mixed).reason.startswith("mixed ensemble (F-2)")


def test_second_order_overdamped_centroid_rate_prop_2_1_i():
    data = _scene_data(2, 3, 1, 1.0, 3.0, {"within": 0.1}, order=2)    # m = 0.5, gamma = 3
    scene = load_scene(data)
    rate = certify(scene.model, scene.initial, scene.tolerance).centroid_rate
    assert rate == pytest.approx((3.0 - math.sqrt(9.0 - 2.0)) / 1.0)


def test_keeper_grants_once_and_never_withdraws():
    scene = load_scene(_scene_data(3, 4, 1, 1.0, 1.0, {"within": 0.1}))
    far = load_scene(_scene_data(3, 4, 1, 1.0, 1.0, "uniform"))
    model = scene.model
    keeper = CertificateKeeper(scene.tolerance)
    assert keeper.refuse(0.0, "realtime") and not keeper.refuse(0.5, "realtime")
    assert keeper.current.reason == "realtime" and not keeper.granted
    assert keeper.observe(model, far.initial, 5.0) and not keeper.granted
    assert not keeper.observe(model, far.initial, 5.0)           # the same refusal: no news
    start = State(2.0, scene.initial.groups)
    granted = keeper.observe(model, start, 1.0)
    assert granted and keeper.granted
    cert = keeper.current
    assert isinstance(cert, Certificate) and cert.t0 == 2.0 and cert.time > 2.0
    assert not keeper.observe(model, State(3.0, far.initial.groups), 1e-3)
    assert keeper.current is cert                                  # kept, not re-evaluated
    assert not keeper.refuse(4.0, "anything") and keeper.current is cert
    assert keeper.breach is None
    late = float(cert.bound(5.0))
    assert keeper.observe(model, State(5.0, ()), late * 1.1)       # a breach is news, once
    assert keeper.breach == (5.0, late * 1.1, late)
    assert not keeper.observe(model, State(6.0, ()), late * 1.1)
    assert keeper.current is cert and keeper.granted


def test_ceil_significant_never_rounds_a_guarantee_down():
    assert [ceil_significant(x) for x in (13.17, 13.2, 0.0012341, 12345.0, 99.95, 0.0)] == \
        ["13.2", "13.2", "0.00124", "12400", "100", "0"]


def test_simulate_and_explain_print_the_certificate(capsys):
    from polymatch_ros.cli import main
    assert main(["explain", "simplices_4d"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == ("certified: matching diameter < 1e-06 by t <= 16.1 "
                       "(Thm 4.2, Props 2.1 (ii), 2.2 (ii))")
    assert main(["simulate", "congruent_triangles", "-q", "--t-end", "0.1"]) == 3
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith("did not converge")
    assert out[-2] == ("not certified: D0 = 2.83 >= 1 (Thm 4.2 needs max |O_i - O_j|_F < 1); "
                      "phases spread over 4.62 >= pi (not within an open half-circle)")
