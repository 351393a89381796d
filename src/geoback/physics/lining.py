"""The lining: a ring of its real thickness meshed with quadratic triangles, condensed onto the
tunnel wall, and the hoop thrust N, shear V and bending moment M around it.

Why a meshed ring (not beam elements along the wall): the ring's outer nodes ARE the ground's wall
nodes, so the lining is conforming with the P2 ground exactly (a 2-node beam is not: its normal
displacement is cubic along an edge whose ground displacement is quadratic); it has the lining's
real geometry (outer face on the excavated wall, no offset of the beam axis, thick or thin); it
needs no new element type, no rotational dofs and no shear- or membrane-locking remedies; and a
stage that activates elements is the same mechanism an elastoplastic simulation or a heading and
bench sequence needs. N, V and M are stress resultants over the thickness, averaged over each
sector from the elements' quadrature points; the tests check them against closed-form thick-ring
solutions (thrust within 1.5e-3, moment within 6e-3 of its largest value, walls of R/16 elements).

Numerics. The ring is structured: `layers` elements through the thickness, one sector per wall
edge, each sector-layer quad (nine P2 nodes on circles) split into two P2 triangles. Only the
outer nodes touch the ground, so the ring enters the ground's equations as a dense matrix S on the
wall dofs (static condensation, exact):

    (K_ground + U S U^t) u = f,    S = K_oo - K_oi K_ii^-1 K_io,    u_inner = -K_ii^-1 K_io u_wall.

S is linear in the lining's E (its derivative is exact: dS = dK_oo - dK_oi X - X^t dK_io + X^t dK_ii X
with X = K_ii^-1 K_io). ``staged.py`` solves the system with the ground's factorisation.

Sign conventions of the outputs: N is the hoop thrust, compression positive [kN/m]; M is the
bending moment about the lining's centreline, positive when the inner face (intrados) is in tension
[kNm/m]; V is the shear force, the integral of the shear stress sigma_r-theta [kN/m]. Sections are
given by their angle from the crown (0 deg crown, 90 deg springline, 180 deg invert) and their arc
length along the centreline from the crown [m].
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from geoback.physics.fem import FEModel, reference_basis
from geoback.physics.shapes import Element, triangle_rule
from geoback.physics.ground import plane_strain_isotropic
from geoback.physics.mesh import Mesh

@dataclass(frozen=True)
class RingMesh:
    """The lining's elements. nodes: ring-local coordinates, the first `n_wall` being the ground's
    wall nodes `wall_nodes` (global ids); triangles: P2, ring-local ids; level_nodes[l, w]: ring-local
    id of the node at radius level l (0 = the wall, 2*layers = the intrados) and wall position w
    (wall nodes ordered from the crown to the invert); angles: polar angle of each wall position."""

    nodes: np.ndarray
    triangles: np.ndarray
    wall_nodes: np.ndarray
    level_nodes: np.ndarray
    radii: np.ndarray
    angles: np.ndarray
    sector: np.ndarray  # (ne,) sector (wall edge, from the crown) of each element
    layer: np.ndarray  # (ne,) element layer, 0 at the wall
    centre: np.ndarray
    radius: float
    thickness: float

    @property
    def n_wall(self) -> int:
        return len(self.wall_nodes)

    @property
    def centreline(self) -> float:
        return self.radius - self.thickness / 2


def ring_mesh(mesh: Mesh, centre, radius: float, thickness: float, layers: int) -> RingMesh:
    """A ring of `layers` P2 elements through `thickness` inside the wall of `mesh` (order 2)."""
    if mesh.order != 2:
        raise ValueError("a lining needs quadratic elements (mesh order 2)")
    c = np.asarray(centre, float)
    edges = mesh.tunnel_edges  # (nf, 3): vertices, mid
    phi = lambda ids: np.arctan2(mesh.nodes[ids, 1] - c[1], mesh.nodes[ids, 0] - c[0])  # noqa: E731
    # orient each edge from the crown side (larger polar angle) to the invert side, sort from the crown
    a, b, m = edges[:, 0].copy(), edges[:, 1].copy(), edges[:, 2]
    swap = phi(a) < phi(b)
    a[swap], b[swap] = edges[swap, 1], edges[swap, 0]
    order = np.argsort(-phi(m))
    a, b, m = a[order], b[order], m[order]
    if np.any(a[1:] != b[:-1]):
        raise ValueError("the tunnel wall is not one chain of edges from the crown to the invert")
    wall = np.empty(2 * len(a) + 1, np.int64)  # crown vertex, mid, vertex, mid, ..., invert vertex
    wall[0:-1:2], wall[1::2], wall[-1] = a, m, b[-1]
    n_wall, nlev = len(wall), 2 * layers + 1
    radii = radius - thickness * np.arange(nlev) / (2 * layers)
    level = np.empty((nlev, n_wall), np.int64)
    level[0] = np.arange(n_wall)
    level[1:] = n_wall + np.arange((nlev - 1) * n_wall).reshape(nlev - 1, n_wall)
    p = mesh.nodes[wall] - c
    dist = np.hypot(p[:, 0], p[:, 1])
    nodes = np.vstack([mesh.nodes[wall]] + [c + p * (r / dist)[:, None] for r in radii[1:]])
    tris, sector, lay = [], [], []
    for s in range(len(a)):
        ia, im, ib = 2 * s, 2 * s + 1, 2 * s + 2
        for ly in range(layers):
            o, h, i = 2 * ly, 2 * ly + 1, 2 * ly + 2
            Oa, Om, Ob = level[o, ia], level[o, im], level[o, ib]
            Sa, C, Sb = level[h, ia], level[h, im], level[h, ib]
            Ia, Im, Ib = level[i, ia], level[i, im], level[i, ib]
            tris += [[Oa, Ob, Ib, Om, Sb, C], [Oa, Ib, Ia, C, Im, Sa]]
            sector += [s, s]
            lay += [ly, ly]
    tri = np.array(tris, np.int64)
    q = nodes[tri[:, :3]]
    area2 = (q[:, 1, 0] - q[:, 0, 0]) * (q[:, 2, 1] - q[:, 0, 1]) - (q[:, 2, 0] - q[:, 0, 0]) * (q[:, 1, 1] - q[:, 0, 1])
    flip = area2 < 0
    tri[flip] = tri[flip][:, [0, 2, 1, 5, 4, 3]]
    return RingMesh(nodes, tri, wall, level, radii, np.arctan2(p[:, 1], p[:, 0]), np.array(sector), np.array(lay),
                    c, float(radius), float(thickness))


@dataclass(frozen=True)
class LiningForces:
    """Section forces of the lining after every stage it acts in (readers only: CSV, VTU, figure).

    angle: (ns,) from the crown [deg]; arc: (ns,) along the centreline from the crown [m];
    points: (ns, 2) on the centreline; N, V, M: (nstages, ns) [kN/m, kN/m, kNm/m] for `stages`;
    displacement: (nstages, ns, 2) of the centreline since the lining was installed [m]."""

    name: str
    thickness: float
    E: float
    nu: float
    radius: float  # of the centreline
    stages: list[str]
    angle: np.ndarray
    arc: np.ndarray
    points: np.ndarray
    N: np.ndarray
    V: np.ndarray
    M: np.ndarray
    displacement: np.ndarray
    values: dict = field(default_factory=dict)  # the named values they were computed at

    def extremes(self, k: int = -1) -> dict:
        """Largest thrust and moments of stage k with where they are."""
        N, M = self.N[k], self.M[k]
        i, j, l = int(np.argmax(N)), int(np.argmax(M)), int(np.argmin(M))
        return {"N_max": (float(N[i]), float(self.angle[i])), "M_max": (float(M[j]), float(self.angle[j])),
                "M_min": (float(M[l]), float(self.angle[l]))}


class RingModel:
    """The lining's stiffness on the wall dofs of a ground model `fe` (see the module docstring)."""

    def __init__(self, fe: FEModel, lining, width: float, depth: float):
        self.spec = lining
        self.mesh = ring_mesh(fe.mesh, fe.centre, fe.radius, lining.thickness, lining.layers)
        rm = self.mesh
        outer = np.array([[rm.level_nodes[0, 0], rm.level_nodes[0, 1], rm.level_nodes[0, 2]]])  # any edge
        self.fe = FEModel(Mesh(rm.nodes, rm.triangles, np.zeros(len(rm.triangles), np.int32), ("lining",),
                               outer, "lining"), width, depth, tuple(fe.centre), fe.radius)
        free = self.fe.free  # ring-local dofs
        node = free // 2
        self.o = np.flatnonzero(node < rm.n_wall)  # positions (in the ring's free dofs) on the wall
        self.i = np.flatnonzero(node >= rm.n_wall)
        ground_dofs = 2 * rm.wall_nodes[node[self.o]] + free[self.o] % 2
        self.wall_dofs = fe.free_index[ground_dofs]  # the ground's free dofs the ring is attached to
        if np.any(self.wall_dofs < 0):
            raise ValueError("the lining's wall nodes are constrained differently in the ground")
        self._ref: tuple | None = None  # (coefficients, K_ii factor, X = K_ii^-1 K_io, S)
        self._sections()

    @property
    def n_wall_dofs(self) -> int:
        return len(self.o)

    # ------------------------------------------------------------------ stiffness
    def coefficients(self, values) -> np.ndarray:
        """(ne, 4) plane-strain D of the lining's elements (complex-safe)."""
        name = self.spec.name
        d = plane_strain_isotropic(values[f"E[{name}]"], values[f"nu[{name}]"])
        return np.tile(np.array(d), (len(self.mesh.triangles), 1))

    def _blocks(self, coeffs: np.ndarray):
        upper = self.fe.matrix(coeffs)
        K = (upper + sp.triu(upper, k=1).T).tocsc()
        return K[self.o][:, self.o].toarray(), K[self.o][:, self.i].toarray(), K[self.i][:, self.i].tocsc()

    def condensed(self, coeffs: np.ndarray) -> np.ndarray:
        """S = K_oo - K_oi K_ii^-1 K_io of the lining with these element coefficients (real)."""
        from geoback.physics.stiffness import proportion

        coeffs = np.asarray(coeffs, float)
        if self._ref is not None:
            s = proportion(coeffs, self._ref[0])
            if s is not None and s > 0:
                return s * self._ref[3]
        Koo, Koi, Kii = self._blocks(coeffs)
        lu = spla.splu(Kii)
        X = lu.solve(np.ascontiguousarray(Koi.T))
        S = Koo - Koi @ X
        S = 0.5 * (S + S.T)
        self._ref = (coeffs, lu, X, S)
        return S

    def condensed_derivative(self, coeffs: np.ndarray, dcoeffs: np.ndarray) -> np.ndarray:
        """dS for a change dcoeffs of the element coefficients (exact: S is condensed from K linear in them)."""
        self.condensed(coeffs)
        X = self._ref[2]
        dKoo, dKoi, dKii = self._blocks(dcoeffs)
        dS = dKoo - dKoi @ X - X.T @ dKoi.T + X.T @ (dKii @ X)
        return 0.5 * (dS + dS.T)

    def ring_displacement(self, u_wall: np.ndarray) -> np.ndarray:
        """The ring's dofs (ring-local, all dofs, fixed ones zero) from its wall dofs; columns allowed."""
        X = self._ref[2]
        u_wall = np.asarray(u_wall, float)
        free = np.zeros((self.fe.nfree,) + u_wall.shape[1:])
        free[self.o] = u_wall
        free[self.i] = -X @ u_wall
        return self.fe.expand(free)

    # ------------------------------------------------------------------ section forces
    def _sections(self) -> None:
        """Section forces are averages over each sector (one wall edge wide, the whole thickness),
        integrated at the elements' quadrature points, where P2 stresses are most accurate:
        N = -(1/dphi) int int sigma_tt dr dphi, with dr dphi = dA / r. Reported at the sector's mid
        angle; the average differs from the value there by O(dphi^2) (under 1e-3 at R/8 elements).
        Checked against the closed-form thick ring (tests/test_staged.py)."""
        rm, fe = self.mesh, self.fe
        X, W = triangle_rule(4)
        nq = len(W)
        elems = np.repeat(np.arange(fe.ne), nq)
        ref = np.tile(X.T, (fe.ne, 1))
        self._strain_ops, det = _strain_operators(fe, elems, ref)
        Nq, _ = reference_basis(Element("triangle", 2), X)
        xq = np.einsum("enx,nq->eqx", fe.nodes[fe.tri], Nq).reshape(-1, 2) - rm.centre
        r = np.hypot(xq[:, 0], xq[:, 1])
        self._phi = np.arctan2(xq[:, 1], xq[:, 0])
        sector = rm.sector[elems]
        nsec = int(rm.sector.max()) + 1
        dphi = rm.angles[0:-1:2] - rm.angles[2::2]  # sector widths (crown to invert: decreasing angle)
        weight = np.abs(det) * np.tile(W, fe.ne) / r / dphi[sector]
        self._sum = sp.csr_matrix((weight, (sector, np.arange(len(r)))), shape=(nsec, len(r)))
        self._lever = rm.centreline - r
        mid = rm.angles[1::2]
        self.section_points = rm.centre + rm.centreline * np.column_stack([np.cos(mid), np.sin(mid)])
        self.section_angle = np.degrees(np.pi / 2 - mid)  # from the crown
        self.section_arc = rm.centreline * np.radians(self.section_angle)
        self._centreline_nodes = rm.level_nodes[self.spec.layers, 1::2]

    def section_forces(self, u_ring: np.ndarray, coeffs: np.ndarray):
        """N (compression +), V, M (intrados in tension +) at the sections from the ring's dofs."""
        exx, eyy, gxy = (op @ u_ring for op in self._strain_ops)
        d11, d22, d12, d33 = np.asarray(coeffs, float)[0]
        sxx, syy, sxy = d11 * exx + d12 * eyy, d12 * exx + d22 * eyy, d33 * gxy
        c, s = np.cos(self._phi), np.sin(self._phi)
        stt = sxx * s * s + syy * c * c - 2 * sxy * s * c
        srt = (syy - sxx) * s * c + sxy * (c * c - s * s)
        return -(self._sum @ stt), self._sum @ srt, self._sum @ (self._lever * stt)

    def centreline_displacement(self, u_ring: np.ndarray) -> np.ndarray:
        nodes = self._centreline_nodes
        return np.column_stack([u_ring[2 * nodes], u_ring[2 * nodes + 1]])

    def element_stress(self, u_ring: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
        """Mean stress (sxx, syy, sxy) of every lining element (since its installation)."""
        eps = self.fe.element_strain(u_ring)
        d11, d22, d12, d33 = np.asarray(coeffs, float).T
        return np.column_stack([d11 * eps[:, 0] + d12 * eps[:, 1], d12 * eps[:, 0] + d22 * eps[:, 1], d33 * eps[:, 2]])


def _strain_operators(fe: FEModel, elems: np.ndarray, ref: np.ndarray):
    """Sparse operators (npts x all dofs) giving exx, eyy, gxy at points (element, reference coords),
    and the Jacobian determinant there."""
    element = Element("triangle", 2)
    _, dN = reference_basis(element, ref.T)  # (nb, 2, n)
    coords = fe.nodes[fe.tri[elems]]  # (n, nb, 2)
    J = np.einsum("enx,nre->exr", coords, dN)  # d x / d xi
    inv = np.linalg.inv(J)  # d xi / d x: inv[e, r, x]
    dNdx = np.einsum("nre,erx->enx", dN, inv)  # (n, nb, 2)
    n, nb = dNdx.shape[:2]
    rows = np.repeat(np.arange(n), nb)
    nodes = fe.tri[elems].ravel()
    shape = (n, fe.ndof)
    dx, dy = dNdx[:, :, 0].ravel(), dNdx[:, :, 1].ravel()
    exx = sp.csr_matrix((dx, (rows, 2 * nodes)), shape=shape)
    eyy = sp.csr_matrix((dy, (rows, 2 * nodes + 1)), shape=shape)
    gxy = sp.csr_matrix((np.concatenate([dy, dx]), (np.concatenate([rows, rows]),
                                                    np.concatenate([2 * nodes, 2 * nodes + 1]))), shape=shape)
    return (exx, eyy, gxy), np.linalg.det(J)
