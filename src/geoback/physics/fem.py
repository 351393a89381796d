"""Plane-strain linear-elastic FEM of the one-step excavation (eqns 31-33).

Isoparametric triangles (P2 by default, curved along the tunnel) assembled vectorised over all
elements at once. The stiffness is kept as four per-element component matrices,

    K = sum_e [ D11_e K11_e + D22_e K22_e + D12_e K12_e + D33_e K33_e ],

with D the element's plane-strain constitutive matrix in Voigt form (xx, yy, xy). Any
orthotropic-in-xy material (isotropic, cross-anisotropic, moduli graded with depth) is then
a per-element coefficient array, K for new parameters is formed without re-assembly, and
dK/dp = sum_e dD_e/dp K_e is exact (eqn 36). The excavation load is the release of the
initial stress on the tunnel wall, f = -int_S N^t sigma0 n dS (eqn 33, n outward of the
ground), linear in sigma_v and in K0*sigma_v at the wall's quadrature points (eqns 39-40).
Shape functions and quadrature rules are in ``shapes.py``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from geoback.physics.shapes import Element, line_rule, triangle_rule

from geoback.physics.mesh import Mesh


def reference_basis(element: Element, X: np.ndarray):
    """Values (nb, nq) and reference gradients (nb, 2|1, nq) of an element's shape functions."""
    return element.basis(X)


def _tri_element(order: int) -> Element:
    return Element("triangle", order)


def _geometry(coords: np.ndarray, dN: np.ndarray):
    """Jacobian inverse and determinant at quadrature points: coords (ne, nb, 2), dN (nb, 2, nq)."""
    J = np.einsum("enx,nrq->eqxr", coords, dN)  # J[e,q,x,r] = d x_x / d xi_r
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    inv = np.empty_like(J)
    inv[..., 0, 0] = J[..., 1, 1] / det
    inv[..., 1, 1] = J[..., 0, 0] / det
    inv[..., 0, 1] = -J[..., 0, 1] / det
    inv[..., 1, 0] = -J[..., 1, 0] / det
    return inv, det  # inv[e,q,r,x] = d xi_r / d x_x


class OutsideMesh(ValueError):
    """A point where displacements are asked lies outside the meshed ground (``point``: its x, y), so
    that a caller who knows where the point comes from can say so (the survey: which instrument)."""

    def __init__(self, point):
        self.point = (float(point[0]), float(point[1]))
        super().__init__(f"point ({self.point[0]:g}, {self.point[1]:g}) lies outside the meshed ground")


class FEModel:
    """Assembled operators of one mesh. Dofs are (ux, uy) per node: dof = 2*node + component."""

    def __init__(self, mesh: Mesh, width: float, depth: float, tunnel_centre: tuple[float, float],
                 radius: float, chunk: int = 40000, x_min: float = 0.0, priority: np.ndarray | None = None):
        self.mesh = mesh
        self.order = mesh.order
        self.nodes = mesh.nodes
        self.tri = mesh.triangles
        self.ne = len(self.tri)
        self.ndof = 2 * len(self.nodes)
        self.width, self.depth = width, depth
        self.centre, self.radius = np.asarray(tunnel_centre, float), radius
        self.element = _tri_element(self.order)
        nb = self.tri.shape[1]
        self._X, self._W = triangle_rule(2 * self.order)
        _, self._dN = reference_basis(self.element, self._X)

        # boundary conditions: symmetry axis and far side ux = 0, bottom fixed
        x, y = self.nodes[:, 0], self.nodes[:, 1]
        tol = 1e-9 * max(width, depth)
        fixed = np.zeros(self.ndof, bool)
        fixed[2 * np.flatnonzero((np.abs(x - x_min) < tol) | (np.abs(x - width) < tol))] = True
        # which element answers for a point several elements hold (on a boundary): the highest priority
        self.priority = np.zeros(len(mesh.triangles)) if priority is None else np.asarray(priority, float)
        bottom = np.flatnonzero(np.abs(y + depth) < tol)
        fixed[2 * bottom] = True
        fixed[2 * bottom + 1] = True
        self.fixed = fixed
        self.free = np.flatnonzero(~fixed)
        self.nfree = len(self.free)
        free_index = -np.ones(self.ndof, np.int64)
        free_index[self.free] = np.arange(self.nfree)
        self.free_index = free_index

        # element dofs (ne, 2nb) in local order [n0x, n0y, n1x, n1y, ...]
        edofs = np.empty((self.ne, 2 * nb), np.int64)
        edofs[:, 0::2] = 2 * self.tri
        edofs[:, 1::2] = 2 * self.tri + 1
        self.edofs = edofs
        redofs = free_index[edofs]

        # upper-triangle entries of the reduced global matrix contributed by each element: the local
        # pairs i <= j (the component matrices are symmetric), placed at (min, max) of their global dofs
        iu, ju = np.triu_indices(2 * nb)
        ra, rb = redofs[:, iu], redofs[:, ju]
        lo, hi = np.minimum(ra, rb), np.maximum(ra, rb)
        del ra, rb
        keep = lo >= 0  # both dofs free (hi >= lo)
        self._entry_elem = np.repeat(np.arange(self.ne, dtype=np.int32), keep.sum(axis=1))
        keys = lo[keep] * self.nfree + hi[keep]
        del lo, hi
        uniq, slots = np.unique(keys, return_inverse=True)
        del keys
        self._slots = slots.astype(np.int64)
        rows = uniq // self.nfree
        self._indices = (uniq % self.nfree).astype(np.int32)
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=self.nfree))]).astype(np.int32)
        self.nnz = len(uniq)

        # component matrices per element, kept only at the entries used above
        self._values = np.empty((4, len(self._slots)))
        pos = 0
        sources = self._pair_sources(iu, ju)
        for start in range(0, self.ne, chunk):
            sl = slice(start, min(start + chunk, self.ne))
            local = self._local_components(sl, sources)  # (4, n, pairs)
            k = keep[sl]
            n_here = int(k.sum())
            self._values[:, pos:pos + n_here] = local[:, k]
            pos += n_here

        coords = self.nodes[self.tri]
        self.centroid = coords[:, :3].mean(axis=1)
        self.region = mesh.region
        self._tree = None
        self._extent = None  # each element's widened extent, for points the nearest centroids miss
        if len(mesh.tunnel_edges):
            self._build_wall()
        else:
            self.wall_points = np.zeros((0, 2))

    # ------------------------------------------------------------------ assembly
    def _strain_operators(self, sl: slice):
        """exx, eyy, gxy of every local vector shape function at quadrature points, and weights."""
        return self.element_quadrature(np.arange(self.ne)[sl])[:4]

    def _nodal_products(self, sl: slice) -> np.ndarray:
        """M_xx, M_yy, M_xy, M_yx per element (n, 4 * nb * nb, flattened), M_xy[a, b] = int N_a,x N_b,y."""
        coords = self.nodes[self.tri[sl]]
        inv, det = _geometry(coords, self._dN)
        dNdx = np.einsum("nrq,eqrx->enxq", self._dN, inv)  # (n, nb, 2, nq)
        w = (np.abs(det) * self._W)[:, None, :]
        gx, gy = dNdx[:, :, 0], dNdx[:, :, 1]
        Mxx = (gx * w) @ gx.transpose(0, 2, 1)
        Myy = (gy * w) @ gy.transpose(0, 2, 1)
        Mxy = (gx * w) @ gy.transpose(0, 2, 1)
        n = len(gx)
        out = np.empty((n, 4) + Mxx.shape[1:])
        out[:, 0], out[:, 1], out[:, 2], out[:, 3] = Mxx, Myy, Mxy, Mxy.transpose(0, 2, 1)
        return out.reshape(n, -1)

    def _pair_sources(self, iu: np.ndarray, ju: np.ndarray) -> np.ndarray:
        """For each component (K11, K22, K12 + K12^t, K33) and local dof pair (i, j), the column of
        _nodal_products it equals, or the last (a zero) where the component has no entry. With dof
        2a = a_x, 2a + 1 = a_y: K11[a_x, b_x] = M_xx; K22[a_y, b_y] = M_yy; (K12 + K12^t)[a_x, b_y] =
        M_xy[a, b] and [a_y, b_x] = M_yx[a, b]; K33[a_x, b_x] = M_yy, [a_y, b_y] = M_xx,
        [a_x, b_y] = M_yx, [a_y, b_x] = M_xy (eqn 36's strain operators written node by node)."""
        nb = self.tri.shape[1]
        a, ca, b, cb = iu // 2, iu % 2, ju // 2, ju % 2
        XX, YY, XY, YX = 0, 1, 2, 3
        zero = 4 * nb * nb
        table = {0: {(0, 0): XX}, 1: {(1, 1): YY}, 2: {(0, 1): XY, (1, 0): YX},
                 3: {(0, 0): YY, (1, 1): XX, (0, 1): YX, (1, 0): XY}}
        out = np.full((4, len(iu)), zero, np.int64)
        for c, where in table.items():
            for (u, v), src in where.items():
                sel = (ca == u) & (cb == v)
                out[c, sel] = src * nb * nb + a[sel] * nb + b[sel]
        return out

    def _local_components(self, sl: slice, sources: np.ndarray | None = None) -> np.ndarray:
        """The four component matrices (4, n, 2nb, 2nb), or with `sources` only their entries at the
        pairs `sources` gives (4, n, pairs)."""
        nb = self.tri.shape[1]
        if sources is None:
            iu, ju = np.meshgrid(np.arange(2 * nb), np.arange(2 * nb), indexing="ij")
            full = self._local_components(sl, self._pair_sources(iu.ravel(), ju.ravel()))
            return full.reshape(4, -1, 2 * nb, 2 * nb)
        M = self._nodal_products(sl)
        M = np.concatenate([M, np.zeros((len(M), 1))], axis=1)
        return np.stack([M[:, sources[c]] for c in range(4)])

    def matrix(self, coeffs: np.ndarray) -> sp.csr_matrix:
        """Upper triangle of sum_e sum_c coeffs[e, c] K_c,e on the free dofs (coeffs: (ne, 4))."""
        coeffs = np.asarray(coeffs, float)
        weights = np.zeros(len(self._slots))
        for c in range(4):
            col = coeffs[:, c]
            if np.any(col):
                weights += col[self._entry_elem] * self._values[c]
        data = np.bincount(self._slots, weights=weights, minlength=self.nnz)
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(self.nfree, self.nfree))

    @staticmethod
    def symmetric_product(upper: sp.csr_matrix, u: np.ndarray) -> np.ndarray:
        """K @ u from the upper triangle of symmetric K."""
        return upper @ u + upper.T @ u - upper.diagonal()[:, None] * u if u.ndim == 2 else \
            upper @ u + upper.T @ u - upper.diagonal() * u

    def element_quadrature(self, elements: np.ndarray):
        """For the elements listed: strain operators exx, eyy, gxy (n, 2nb, nq) of every local vector
        shape function at the quadrature points, the weights w (n, nq) (|det J| times the rule's), the
        shape values N (nb, nq) and the quadrature points' coordinates (n, nq, 2)."""
        elements = np.asarray(elements, np.int64)
        coords = self.nodes[self.tri[elements]]
        inv, det = _geometry(coords, self._dN)
        dNdx = np.einsum("nrq,eqrx->enxq", self._dN, inv)
        n, nb, _, nq = dNdx.shape
        exx = np.zeros((n, 2 * nb, nq))
        eyy = np.zeros_like(exx)
        gxy = np.zeros_like(exx)
        exx[:, 0::2] = dNdx[:, :, 0]
        eyy[:, 1::2] = dNdx[:, :, 1]
        gxy[:, 0::2] = dNdx[:, :, 1]
        gxy[:, 1::2] = dNdx[:, :, 0]
        N, _ = reference_basis(self.element, self._X)
        xq = np.einsum("enx,nq->eqx", coords, N)
        return exx, eyy, gxy, np.abs(det) * self._W, N, xq

    # ------------------------------------------------------------------ loads
    def _build_wall(self):
        """Quadrature on the excavated boundary: points, weights, normals, shape values."""
        edges = self.mesh.tunnel_edges
        line = Element("line", self.order)
        X, W = line_rule(2 * self.order + 2)
        N, dN = reference_basis(line, X)  # (nb, nq), (nb, 1, nq)
        coords = self.nodes[edges]  # (nf, nb, 2)
        xq = np.einsum("fnx,nq->fqx", coords, N)
        tq = np.einsum("fnx,nq->fqx", coords, dN[:, 0])
        jac = np.linalg.norm(tq, axis=2)
        normal = np.stack([tq[..., 1], -tq[..., 0]], axis=-1) / jac[..., None]
        # outward normal of the ground points into the tunnel (towards its centre)
        inward = np.einsum("fqx,fqx->fq", normal, self.centre - xq) > 0
        normal[~inward] *= -1
        self.wall_points = xq.reshape(-1, 2)
        dS = (jac * W).reshape(-1)
        nrm = normal.reshape(-1, 2)
        nf, nq = xq.shape[:2]
        nb = edges.shape[1]
        Nq = np.broadcast_to(N.T[None], (nf, nq, nb)).reshape(-1, nb)  # (nf*nq, nb)
        node = np.repeat(edges, nq, axis=0)  # (nf*nq, nb)
        qidx = np.repeat(np.arange(nf * nq)[:, None], nb, axis=1)
        # f = -int N^t sigma0 n dS with sigma0 n = (K0 sv nx, sv ny)
        rows_x = self.free_index[2 * node]
        rows_y = self.free_index[2 * node + 1]
        vx = -(Nq * (nrm[:, 0] * dS)[:, None])
        vy = -(Nq * (nrm[:, 1] * dS)[:, None])
        shape = (self.nfree, nf * nq)
        mx, my = rows_x >= 0, rows_y >= 0
        self._load_h = sp.csr_matrix((vx[mx], (rows_x[mx], qidx[mx])), shape=shape)
        self._load_v = sp.csr_matrix((vy[my], (rows_y[my], qidx[my])), shape=shape)

    def load(self, sigma_v: np.ndarray, sigma_h: np.ndarray) -> np.ndarray:
        """Excavation load (free dofs) from the initial vertical and horizontal stress at the
        wall points: f = -int N^t sigma0 n dS (eqn 33); sigma_h = K0 sigma_v (eqns 39-40)."""
        return self._load_v @ sigma_v + self._load_h @ sigma_h

    # ------------------------------------------------------------------ fields and points
    def expand(self, u_free: np.ndarray) -> np.ndarray:
        """Free-dof vector(s) -> all dofs (fixed ones zero)."""
        shape = (self.ndof,) + u_free.shape[1:]
        u = np.zeros(shape, dtype=u_free.dtype)
        u[self.free] = u_free
        return u

    def element_strain(self, u: np.ndarray) -> np.ndarray:
        """Mean strain (exx, eyy, gxy) of every element from the full dof vector u."""
        out = np.empty((self.ne, 3))
        for start in range(0, self.ne, 40000):
            sl = slice(start, min(start + 40000, self.ne))
            exx, eyy, gxy, w = self._strain_operators(sl)
            ue = u[self.edofs[sl]]
            area = w.sum(axis=1)
            for i, op in enumerate((exx, eyy, gxy)):
                out[sl, i] = np.einsum("eaq,ea,eq->e", op, ue, w) / area
        return out

    def locate(self, points: np.ndarray, tol: float = 1e-9):
        """Element and reference coordinates of each point; element -1 where outside the mesh."""
        points = np.atleast_2d(np.asarray(points, float))
        # with priorities (elements excavated at different stages), a point on a wall is held by small
        # elements of an opening's lining as well: look further for the ground's
        k = min(12 if not np.any(self.priority != self.priority[0]) else 40, self.ne)
        cand = self._nearest_elements(points, k)
        elem = -np.ones(len(points), np.int64)
        ref = np.zeros((len(points), 2))
        best = np.full(len(points), -np.inf)
        for j in range(k):
            e = cand[:, j]
            xi = self._inverse_map(e, points)
            lam = np.column_stack([1 - xi.sum(axis=1), xi])
            score = lam.min(axis=1)
            better = (score > best) & (elem < 0)
            inside = score >= -tol
            # a point on a wall (within 1e-6 of an element's size of it) is read from the element that stays longer
            preferred = (elem >= 0) & (self.priority[e] > self.priority[np.maximum(elem, 0)]) & (score >= -1e-6)
            take = (better & inside) | preferred
            elem[take], ref[take] = e[take], xi[take]
            best = np.where(better, score, best)
        lost = np.flatnonzero(elem < 0)
        if lost.size and k < self.ne:
            elem[lost], ref[lost] = self._locate_by_extent(points[lost], tol)
        return elem, ref

    def _locate_by_extent(self, points: np.ndarray, tol: float):
        """Points the nearest centroids did not contain, tried in every element whose extent holds them.
        A long, thin element (a 0.5 m layer meshed at 10 m far from the tunnel) has its centroid farther
        from a point inside it than a dozen smaller elements' centroids: the point was reported 'outside
        the meshed ground' although it is inside. (The extent is widened by a quarter of its size, for
        curved quadratic edges bulging past their nodes.) A point the case accepts on the tunnel wall or a
        boundary within its tolerance (a relative 1e-6) may lie that little outside the meshed wall; within
        ``SNAP`` of an element (in its reference coordinates) it is read at the element's nearest point,
        as the displacement field is continuous there; farther out it stays outside."""
        if self._extent is None:
            xy = self.nodes[self.tri]  # (ne, nb, 2)
            lo, hi = xy.min(axis=1), xy.max(axis=1)
            pad = 0.25 * (hi - lo).max(axis=1, keepdims=True)
            self._extent = (lo - pad, hi + pad)
        lo, hi = self._extent
        elem = -np.ones(len(points), np.int64)
        ref = np.zeros((len(points), 2))
        for i, p in enumerate(points):
            cand = np.flatnonzero(np.all((lo <= p) & (p <= hi), axis=1))
            if not cand.size:
                continue
            xi = self._inverse_map(cand, np.repeat(p[None, :], len(cand), axis=0))
            score = np.column_stack([1 - xi.sum(axis=1), xi]).min(axis=1)
            j = int(np.argmax(score))
            if score[j] >= -tol:
                elem[i], ref[i] = cand[j], xi[j]
            elif score[j] >= -self.SNAP:
                lam = np.maximum(np.array([1 - xi[j].sum(), *xi[j]]), 0.0)
                elem[i], ref[i] = cand[j], lam[1:] / lam.sum()
        return elem, ref

    SNAP = 1e-4  # reference-coordinate distance within which a point just outside an element is read at its edge

    BRUTE_FORCE = 20000  # elements below which candidates are found by brute force (no KD-tree to import)

    def _nearest_elements(self, points: np.ndarray, k: int) -> np.ndarray:
        """Indices (npts, k) of the k elements whose centroids are nearest each point."""
        if self.ne > self.BRUTE_FORCE:
            if self._tree is None:
                from scipy.spatial import cKDTree

                self._tree = cKDTree(self.centroid)
            return self._tree.query(points, k=k)[1].reshape(len(points), k)
        out = np.empty((len(points), k), np.int64)
        for start in range(0, len(points), 64):
            chunk = points[start:start + 64]
            d2 = ((chunk[:, None, :] - self.centroid[None, :, :]) ** 2).sum(axis=2)
            near = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < self.ne else np.argsort(d2, axis=1)[:, :k]
            order = np.argsort(np.take_along_axis(d2, near, axis=1), axis=1)
            out[start:start + 64] = np.take_along_axis(near, order, axis=1)
        return out

    def _inverse_map(self, elems: np.ndarray, points: np.ndarray) -> np.ndarray:
        coords = self.nodes[self.tri[elems]]  # (n, nb, 2)
        xi = np.full((len(points), 2), 1 / 3)
        for _ in range(12):
            N, dN = reference_basis(self.element, xi.T)  # (nb, n), (nb, 2, n)
            x = np.einsum("enx,ne->ex", coords, N)
            J = np.einsum("enx,nre->exr", coords, dN)
            delta = np.linalg.solve(J, (points - x)[..., None])[..., 0]
            xi = xi + delta
            if np.abs(delta).max() < 1e-13:
                break
        return xi

    def interpolation(self, points: np.ndarray, derivative: int | None = None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """Sparse operators (npts x nfree) giving ux and uy at points by shape functions; with
        `derivative` (0: x, 1: y) their partial derivatives d ux / d x_derivative, d uy / d x_derivative
        instead (the gradient of the element's interpolant: exact, but discontinuous across element
        edges as the P2 field's gradient is)."""
        elem, ref = self.locate(points)
        if np.any(elem < 0):
            raise OutsideMesh(np.atleast_2d(np.asarray(points))[elem < 0][0])
        N, dN = reference_basis(self.element, ref.T)  # (nb, n), (nb, 2, n)
        nodes = self.tri[elem]  # (n, nb)
        if derivative is not None:  # dN/dx_d = sum_r dN/dxi_r dxi_r/dx_d (isoparametric map)
            coords = self.nodes[nodes]  # (n, nb, 2)
            J = np.einsum("enx,nre->exr", coords, dN)  # d x_x / d xi_r
            inv = np.linalg.inv(J)  # (n, r, x): d xi_r / d x_x
            N = np.einsum("nre,er->ne", dN, inv[:, :, derivative])
        rows = np.repeat(np.arange(len(elem)), nodes.shape[1])
        ops = []
        for comp in (0, 1):
            cols = self.free_index[(2 * nodes + comp).ravel()]
            vals = N.T.ravel()
            ok = cols >= 0
            ops.append(sp.csr_matrix((vals[ok], (rows[ok], cols[ok])), shape=(len(elem), self.nfree)))
        return ops[0], ops[1]
