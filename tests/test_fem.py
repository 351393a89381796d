"""Verification of the mesh, the FE model and the solver (geoback.physics.mesh, geoback.physics.fem, geoback.physics.solver).

Closed forms, structural identities and invariants, no regression numbers:

* Kirsch: a deep unlined tunnel under uniform initial stress (DESIGN.md, "Numerics that matter").
* the one-layer structure x(E, K0) = (a + K0 b) / E of eqns (39)-(41);
* determinism and caching of the mesh;
* equilibrium of the excavation load (eqn 33): a uniform stress releases no net vertical force,
  gravity releases the weight of the excavated half-disk;
* the interpolation operator (nodal values, exact P2 reproduction of quadratic fields);
* the two solver backends agree;
* patch test: a linear displacement field is in the kernel of K away from the boundary.
"""
from __future__ import annotations

import numpy as np
import pytest

import geoback.physics.mesh as gmesh
from geoback.case.loading import LoadedCase, case_from_data
from geoback.physics.fem import FEModel
from geoback.physics.ground import plane_strain_isotropic
from geoback.physics.mesh import build_mesh
from geoback.inference.identification import prepare
from geoback.physics.solver import Factorisation, available_backends

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


# ---------------------------------------------------------------------------- helpers / fixtures
@pytest.fixture(scope="module", autouse=True)
def geoback_cache(tmp_path_factory):
    """Keep the mesh cache of this module in a temporary folder (never the home folder)."""
    folder = tmp_path_factory.mktemp("geoback-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GEOBACK_CACHE", str(folder))
        yield folder


def kirsch_case(R=1.0, L=1000.0, size_tunnel=None, size_far=None, nu=0.25, K0=1.0):
    """A deep tunnel: radius R, axis at depth L, half-width L, depth 2L (R/L = 1e-3)."""
    return case_from_data(dict(
        name="kirsch",
        geometry=dict(radius=R, axis_depth=L, width=L, depth=2 * L),
        ground=dict(unit_weight=1.0, K0=K0, layers=[dict(name="rock", top=0.0, E=1000.0, nu=nu)]),
        mesh=dict(size_tunnel=size_tunnel or R / 12, size_far=size_far or L / 10),
    ))


def tunnel_data(size_tunnel=0.6, size_far=5.0, nu=0.3, instruments=None, parameters=None):
    """The geometry of cases/tunnel-paper.yaml (shallow tunnel), coarser mesh for speed."""
    data = dict(
        name="shallow",
        geometry=dict(radius=3.0, axis_depth=10.0, width=40.0, depth=30.0),
        ground=dict(unit_weight=20.0, K0=1.0, layers=[dict(name="clay", top=0.0, E=1.0e4, nu=nu)]),
        mesh=dict(size_tunnel=size_tunnel, size_far=size_far),
    )
    if instruments is not None:
        data["instruments"] = instruments
    if parameters is not None:
        data["parameters"] = parameters
    return data


def model_of(case) -> FEModel:
    g = case.geometry
    return FEModel(build_mesh(case), g.width, g.depth, (0.0, -g.axis_depth), g.radius)


def coefficients(fe: FEModel, E: float, nu: float) -> np.ndarray:
    return np.tile(np.array(plane_strain_isotropic(E, nu), float), (fe.ne, 1))


def kirsch_ur(theta, p0, R, E, nu, K0):
    """Radial wall displacement (outward positive) of the Kirsch solution; theta from the springline."""
    G = E / (2 * (1 + nu))
    return -p0 * R / (4 * G) * ((1 + K0) - (1 - K0) * (3 - 4 * nu) * np.cos(2 * theta))


@pytest.fixture(scope="module")
def kirsch(geoback_cache):
    """Mesh and model of the deep tunnel, with one factorisation per nu (K = E k(nu))."""
    case = kirsch_case()
    fe = model_of(case)
    factors = {}

    def solve(nu, K0, E=1000.0, p0=1.0):
        if nu not in factors:
            factors[nu] = Factorisation(fe.matrix(coefficients(fe, E, nu)))
        sv = -p0 * np.ones(len(fe.wall_points))
        return fe.expand(factors[nu].solve(fe.load(sv, K0 * sv))).reshape(-1, 2)

    return case, fe, solve


@pytest.fixture(scope="module")
def shallow(geoback_cache):
    case = case_from_data(tunnel_data())
    return case, model_of(case)


# ---------------------------------------------------------------------------- Kirsch
K0S = (0.5, 1.0, 2.0)
NUS = (0.25, 0.49)


@pytest.mark.parametrize("nu", NUS)
@pytest.mark.parametrize("K0", K0S)
def test_kirsch_crown_and_springline(kirsch, K0, nu):
    case, fe, solve = kirsch
    R, L = case.geometry.radius, case.geometry.axis_depth
    u = solve(nu, K0)
    nodes = fe.nodes
    crown = np.argmin(np.hypot(nodes[:, 0], nodes[:, 1] + L - R))
    spring = np.argmin(np.hypot(nodes[:, 0] - R, nodes[:, 1] + L))
    assert np.allclose(nodes[crown], [0.0, -L + R], atol=1e-9 * L)
    assert np.allclose(nodes[spring], [R, -L], atol=1e-9 * L)
    # radial outward at the crown is +y, at the springline +x
    expected_crown = kirsch_ur(np.pi / 2, 1.0, R, 1000.0, nu, K0)
    expected_spring = kirsch_ur(0.0, 1.0, R, 1000.0, nu, K0)
    assert u[crown, 1] == pytest.approx(expected_crown, rel=0.01)
    assert u[spring, 0] == pytest.approx(expected_spring, rel=0.01)
    assert u[crown, 0] == 0.0  # on the symmetry axis


@pytest.mark.parametrize("nu", NUS)
@pytest.mark.parametrize("K0", K0S)
def test_kirsch_whole_wall(kirsch, K0, nu):
    case, fe, solve = kirsch
    R, L = case.geometry.radius, case.geometry.axis_depth
    u = solve(nu, K0)
    wall = np.unique(fe.mesh.tunnel_edges)
    d = fe.nodes[wall] - np.array([0.0, -L])
    r = np.hypot(d[:, 0], d[:, 1])
    assert np.allclose(r, R, rtol=1e-9)  # wall nodes (also mid-side ones) lie on the circle
    theta = np.arctan2(d[:, 1], d[:, 0])
    assert theta.min() < -np.pi / 2 + 1e-9 and theta.max() > np.pi / 2 - 1e-9  # crown to invert
    ur = np.einsum("nx,nx->n", u[wall], d) / r
    exact = kirsch_ur(theta, 1.0, R, 1000.0, nu, K0)
    assert np.abs(ur - exact).max() <= 0.015 * np.abs(exact).max()


# ---------------------------------------------------------------------------- structure (eqns 39-41)
def test_one_layer_readings_are_a_plus_k0_b_over_e(geoback_cache):
    instruments = [
        dict(name="P1", kind="points", points=[[5.0, -3.0], [0.0, -5.0], [6.0, -10.0], [12.0, -18.0]],
             sigma=0.001),
        dict(name="I1", kind="inclinometer", x=5.0, toe_depth=24.0, spacing=3.0, stations=7, sigma=0.001),
        dict(name="X1", kind="extensometer", start=[0.0, 0.0], end=[0.0, -6.5], spacing=1.25, stations=5,
             sigma=0.0005),
    ]
    parameters = [dict(name="E", initial=5.0e3), dict(name="K0", initial=0.5)]
    case = case_from_data(tunnel_data(instruments=instruments, parameters=parameters))
    problem = prepare(LoadedCase(case, None, {}))
    assert problem.parameters.names == ["E[clay]", "K0"]

    E1, K1, K2 = 5.0e3, 0.5, 1.5
    x1 = problem.predict(np.array([E1, K1])).x
    x2 = problem.predict(np.array([E1, K2])).x
    b = E1 * (x2 - x1) / (K2 - K1)
    a = E1 * x1 - K1 * b
    assert np.abs(b).max() > 1e-3 * np.abs(a).max()  # K0 really matters

    for E3, K3 in ((2.3e4, 0.8), (7.1e2, 2.7)):
        x3 = problem.predict(np.array([E3, K3])).x
        expected = (a + K3 * b) / E3
        assert np.abs(x3 - expected).max() <= 1e-10 * np.abs(x3).max()

    # E scales K only: a single factorisation served every prediction (eqn 41)
    assert problem.simulation.counters.factorisations == 1


def test_one_layer_sensitivities_follow_the_structure(geoback_cache):
    """dx/dE = -x/E and dx/dK0 = b/E, by back-substitution only (eqns 34-42)."""
    instruments = [dict(name="P1", kind="points", points=[[5.0, -3.0], [6.0, -10.0], [0.0, -15.0]],
                        sigma=0.001)]
    parameters = [dict(name="E", initial=5.0e3), dict(name="K0", initial=0.5)]
    case = case_from_data(tunnel_data(instruments=instruments, parameters=parameters))
    problem = prepare(LoadedCase(case, None, {}))
    E, K0 = 8.0e3, 0.7
    pred = problem.predict(np.array([E, K0]), sensitivities=True)
    x, A = pred.x, pred.A
    x_h = problem.predict(np.array([E, K0 + 1.0])).x
    b = E * (x_h - x)  # exact, x is linear in K0
    scale = np.abs(x).max()
    assert np.abs(A[:, 0] + x / E).max() <= 1e-10 * scale / E
    assert np.abs(A[:, 1] - b / E).max() <= 1e-10 * np.abs(b / E).max()
    assert problem.simulation.counters.factorisations == 1


# ---------------------------------------------------------------------------- mesh determinism and cache
def test_mesh_is_deterministic_without_cache():
    case = case_from_data(tunnel_data(size_tunnel=0.5, size_far=4.0))
    calls = gmesh.GMSH_CALLS
    m1 = build_mesh(case, use_cache=False)
    m2 = build_mesh(case, use_cache=False)
    assert gmesh.GMSH_CALLS == calls + 2
    assert m1.key == m2.key
    for name in ("nodes", "triangles", "region", "tunnel_edges"):
        assert np.array_equal(getattr(m1, name), getattr(m2, name)), name
    assert m1.region_names == m2.region_names
    assert m1.order == 2 and m1.triangles.shape[1] == 6


def test_mesh_cache_avoids_gmsh(tmp_path, monkeypatch):
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path))
    case = case_from_data(tunnel_data(size_tunnel=0.55, size_far=4.5))
    calls = gmesh.GMSH_CALLS
    m1 = build_mesh(case)
    assert gmesh.GMSH_CALLS == calls + 1
    assert len(list((tmp_path / "meshes").glob("*.npz"))) == 1
    m2 = build_mesh(case)
    assert gmesh.GMSH_CALLS == calls + 1  # served from the cache
    for name in ("nodes", "triangles", "region", "tunnel_edges"):
        a, b = getattr(m1, name), getattr(m2, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert m1.region_names == m2.region_names and m1.key == m2.key
    # and the cached mesh equals a fresh gmsh run
    m3 = build_mesh(case, use_cache=False)
    assert np.array_equal(m1.nodes, m3.nodes) and np.array_equal(m1.triangles, m3.triangles)


def test_mesh_cache_key_follows_inputs(tmp_path, monkeypatch):
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path))
    m1 = build_mesh(case_from_data(tunnel_data(size_tunnel=0.6, size_far=5.0)))
    m2 = build_mesh(case_from_data(tunnel_data(size_tunnel=0.6, size_far=5.0, nu=0.45)))  # nu: same mesh
    m3 = build_mesh(case_from_data(tunnel_data(size_tunnel=0.7, size_far=5.0)))
    assert m1.key == m2.key and m1.key != m3.key


# ---------------------------------------------------------------------------- equilibrium of the load
def _resultant(fe: FEModel, f_free: np.ndarray) -> np.ndarray:
    return fe.expand(f_free).reshape(-1, 2).sum(axis=0)


def test_uniform_stress_releases_no_vertical_force(shallow):
    case, fe = shallow
    sv = np.full(len(fe.wall_points), -150.0)
    f = fe.load(sv, 0.7 * sv)
    Fx, Fy = _resultant(fe, f)
    magnitude = np.abs(f).sum()
    assert magnitude > 0
    assert abs(Fy) <= 1e-12 * magnitude
    # the horizontal resultant is carried by the symmetry axis: about K0 |sv| 2R towards the tunnel
    assert Fx < 0


def test_gravity_releases_the_weight_of_the_excavated_half_disk(shallow):
    case, fe = shallow
    gamma, R = case.ground.unit_weight, case.geometry.radius
    for K0 in (0.4, 1.0, 2.5):
        sv = -gamma * (-fe.wall_points[:, 1])  # sigma_v = -gamma * depth
        Fx, Fy = _resultant(fe, fe.load(sv, K0 * sv))
        assert Fy > 0  # upward
        assert Fy == pytest.approx(gamma * np.pi * R ** 2 / 2, rel=1e-3)


def test_wall_quadrature_points_lie_on_the_wall(shallow):
    case, fe = shallow
    R, d = case.geometry.radius, case.geometry.axis_depth
    rq = np.hypot(fe.wall_points[:, 0], fe.wall_points[:, 1] + d)
    assert np.abs(rq - R).max() <= 1e-3 * R  # quadrature points on the (curved P2) wall
    assert fe.wall_points[:, 0].min() >= -1e-12


# ---------------------------------------------------------------------------- interpolation
def test_interpolation_reproduces_nodal_values(shallow):
    case, fe = shallow
    rng = np.random.default_rng(1)
    u_free = rng.normal(size=fe.nfree)
    Ix, Iy = fe.interpolation(fe.nodes)
    nodal = fe.expand(u_free).reshape(-1, 2)  # fixed dofs are zero
    assert np.abs(Ix @ u_free - nodal[:, 0]).max() <= 1e-10
    assert np.abs(Iy @ u_free - nodal[:, 1]).max() <= 1e-10
    # rows are partitions of unity where no dof is fixed
    free_nodes = ~fe.fixed.reshape(-1, 2).any(axis=1)
    ones = np.ones(fe.nfree)
    assert np.allclose((Ix @ ones)[free_nodes], 1.0, atol=1e-12)


def test_interpolation_is_exact_for_quadratic_fields(shallow):
    case, fe = shallow
    g = case.geometry
    x, y = fe.nodes[:, 0], fe.nodes[:, 1]
    u_full = np.column_stack([x ** 2, x * y]).ravel()  # u = (x^2, xy), zero on the symmetry axis
    u_free = u_full[fe.free]

    rng = np.random.default_rng(7)
    pts = np.column_stack([rng.uniform(0, g.width, 4000), rng.uniform(-g.depth, 0, 4000)])
    pts = pts[np.hypot(pts[:, 0], pts[:, 1] + g.axis_depth) > 1.3 * g.radius]
    elem, _ = fe.locate(pts)
    assert np.all(elem >= 0)
    # keep points in straight-sided elements (none on the tunnel) whose dofs carry the field:
    # a fixed dof is zero in the FE vector, so elements touching fixed non-zero values are skipped
    wall = np.zeros(len(fe.nodes), bool)
    wall[fe.mesh.tunnel_edges.ravel()] = True
    lost = (fe.fixed & (u_full != 0)).reshape(-1, 2).any(axis=1)
    tri = fe.tri[elem]
    keep = ~(wall[tri] | lost[tri]).any(axis=1)
    pts, tri = pts[keep], tri[keep]
    assert len(pts) > 500
    v = fe.nodes
    for (i, j), m in (((0, 1), 3), ((1, 2), 4), ((2, 0), 5)):  # mid-side nodes at mid-points: affine map
        assert np.allclose(v[tri[:, m]], 0.5 * (v[tri[:, i]] + v[tri[:, j]]), rtol=0, atol=1e-12 * g.width)

    Ix, Iy = fe.interpolation(pts)
    ux, uy = Ix @ u_free, Iy @ u_free
    scale = max(g.width, g.depth) ** 2
    assert np.abs(ux - pts[:, 0] ** 2).max() <= 1e-10 * scale
    assert np.abs(uy - pts[:, 0] * pts[:, 1]).max() <= 1e-10 * scale


def test_interpolation_rejects_points_outside(shallow):
    case, fe = shallow
    with pytest.raises(ValueError, match="outside"):
        fe.interpolation(np.array([[1.0, -1.0], [0.5, -case.geometry.axis_depth]]))  # inside the tunnel


# ---------------------------------------------------------------------------- solver backends
@pytest.mark.skipif("pardiso" not in available_backends(), reason="pypardiso is not installed")
def test_backends_agree(shallow):
    case, fe = shallow
    K = fe.matrix(coefficients(fe, 1.0e4, 0.3))
    sv = -case.ground.unit_weight * (-fe.wall_points[:, 1])
    f = np.column_stack([fe.load(sv, 0.6 * sv), fe.load(sv, 1.8 * sv)])
    solutions = {}
    for backend in ("pardiso", "scipy"):
        fact = Factorisation(K, backend)
        assert fact.backend == backend
        solutions[backend] = fact.solve(f)
        assert solutions[backend].shape == f.shape
        fact.release()
    a, b = solutions["pardiso"], solutions["scipy"]
    assert np.linalg.norm(a - b) <= 1e-9 * np.linalg.norm(b)
    # and it is the solution: K u = f (K given by its upper triangle)
    r = fe.symmetric_product(K, b) - f
    assert np.linalg.norm(r) <= 1e-9 * np.linalg.norm(f)


def test_scipy_backend_single_rhs(shallow):
    case, fe = shallow
    K = fe.matrix(coefficients(fe, 1.0e4, 0.3))
    sv = -case.ground.unit_weight * (-fe.wall_points[:, 1])
    f = fe.load(sv, sv)
    u = Factorisation(K, "scipy").solve(f)
    assert u.shape == f.shape
    assert np.linalg.norm(fe.symmetric_product(K, u) - f) <= 1e-9 * np.linalg.norm(f)


# ---------------------------------------------------------------------------- patch test
@pytest.mark.parametrize("nu", (0.0, 0.3, 0.49))
def test_patch_linear_field_has_no_interior_residual(shallow, nu):
    """K u = 0 at every node whose elements see neither a boundary nor a fixed dof, u linear."""
    case, fe = shallow
    g = case.geometry
    a, b, c, d, e0, f0 = 1.3e-3, -0.7e-3, 0.4e-3, 2.1e-3, 0.05, -0.02
    x, y = fe.nodes[:, 0], fe.nodes[:, 1]
    u_full = np.column_stack([a * x + b * y + e0, c * x + d * y + f0]).ravel()

    # uniform strain everywhere (the strain operator itself, fixed dofs included)
    strain = fe.element_strain(u_full)
    assert np.allclose(strain, [a, d, b + c], rtol=0, atol=1e-12)

    K = fe.matrix(coefficients(fe, 1.0e4, nu))
    u_free = u_full[fe.free]
    r = fe.symmetric_product(K, u_free)
    # nodes on any boundary (surface, sides, bottom, tunnel wall) carry tractions or reactions;
    # rows of nodes sharing an element with them also see the fixed dofs left out of K_ff
    tol = 1e-9 * max(g.width, g.depth)
    boundary = ((np.abs(x) < tol) | (np.abs(x - g.width) < tol) | (np.abs(y) < tol)
                | (np.abs(y + g.depth) < tol))
    boundary[fe.mesh.tunnel_edges.ravel()] = True
    touched = np.zeros(len(x), bool)
    touched[fe.tri[boundary[fe.tri].any(axis=1)].ravel()] = True
    inner = np.flatnonzero(~touched)
    assert len(inner) > 0.5 * len(x)
    rows = fe.free_index[np.concatenate([2 * inner, 2 * inner + 1])]
    assert np.all(rows >= 0)
    scale = fe.symmetric_product(abs(K), np.abs(u_free))[rows]
    assert np.abs(r[rows]).max() <= 1e-10 * scale.max()
    # and the boundary rows do carry the traction of the uniform stress (the test is not vacuous)
    assert np.abs(r).max() > 1e-6 * scale.max()


# ---------------------------------------------------------------------------- shape functions and quadrature
def test_shape_functions_and_quadrature_rules():
    """Kronecker property at the nodes, partition of unity, gradients against differences, and the
    rules integrate monomials exactly up to their degree (x^a y^b over the triangle: a! b! / (a+b+2)!)."""
    from math import factorial

    from geoback.physics.shapes import Element, line_rule, triangle_rule

    nodes = {("triangle", 1): [[0, 1, 0], [0, 0, 1]], ("triangle", 2): [[0, 1, 0, .5, .5, 0], [0, 0, 1, 0, .5, .5]],
             ("line", 1): [[0, 1]], ("line", 2): [[0, 1, .5]]}
    rng = np.random.default_rng(3)
    for (cell, order), X in nodes.items():
        e = Element(cell, order)
        N, _ = e.basis(np.array(X, float))
        np.testing.assert_allclose(N, np.eye(e.nodes), atol=1e-15)
        P = rng.random((len(X), 7)) * (0.5 if cell == "triangle" else 1)
        N, dN = e.basis(P)
        np.testing.assert_allclose(N.sum(axis=0), 1.0, atol=1e-14)
        for k in range(len(X)):
            h = np.zeros((len(X), 1))
            h[k] = 1e-6
            fd = (e.basis(P + h)[0] - e.basis(P - h)[0]) / 2e-6
            np.testing.assert_allclose(dN[:, k], fd, atol=1e-8)
    for degree in (2, 4):
        X, W = triangle_rule(degree)
        for a in range(degree + 1):
            for b in range(degree + 1 - a):
                exact = factorial(a) * factorial(b) / factorial(a + b + 2)
                assert W @ (X[0] ** a * X[1] ** b) == pytest.approx(exact, rel=1e-13)
    X, W = line_rule(6)
    for a in range(7):
        assert W @ X[0] ** a == pytest.approx(1 / (a + 1), rel=1e-13)
