"""Quadrature-point operators of an :class:`~geoback.physics.fem.FEModel` for non-linear materials.

Adapter over the FE model's private element machinery (``FEModel._strain_operators`` and the
reference basis of ``geoback.physics.fem``), kept here until the FE model exposes it publicly.

Points are numbered element by element, ``point = element * nq + q``. With B the strain
operator at the points (strain = (exx, eyy, gxy) = B u on the free dofs) and w the quadrature
weights (|det J| times the reference weight):

    internal force      F(sigma) = sum_points w B^t (sxx, syy, sxy)       = int B^t sigma dV
    tangent             K(C)     = sum_points w B^t C B                    = int B^t C B dV

with C (3x3 per point) the in-plane rows of d sigma / d strain, possibly non-symmetric; K is
returned as a full CSR matrix on the free dofs with a fixed sparsity pattern. ``restricted`` gives the
same operators for a subset of the elements on the dofs they hold (a stage's body when elements are
removed and activated: ``excavation_plastic.py``).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from geoback.physics.fem import FEModel, reference_basis


class PointOperators:
    """B at every quadrature point, the weights, and the assembly of forces and tangents."""

    def __init__(self, fe: FEModel, chunk: int = 20000):
        self.fe = fe
        self.ne = fe.ne
        nb2 = fe.edofs.shape[1]
        parts_B, parts_w = [], []
        for start in range(0, fe.ne, chunk):
            sl = slice(start, min(start + chunk, fe.ne))
            exx, eyy, gxy, w = fe._strain_operators(sl)  # (n, 2nb, nq) each, w (n, nq)
            parts_B.append(np.stack([exx, eyy, gxy], axis=1).transpose(0, 3, 1, 2))  # (n, nq, 3, 2nb)
            parts_w.append(w)
        self.B = np.concatenate(parts_B)  # (ne, nq, 3, 2nb)
        self.w = np.concatenate(parts_w)  # (ne, nq)
        self.nq = self.B.shape[1]
        self.npts = self.ne * self.nq
        self.nfree = fe.nfree
        self._redofs = fe.free_index[fe.edofs]  # (ne, 2nb), -1 at fixed dofs
        self.elements = None  # the elements of fe these operators cover (None: all of them)
        self._index()

    def _index(self) -> None:
        """The sparse strain operator and the tangent's pattern from B, w and the element dofs."""
        nb2 = self.B.shape[-1]

        # B as a sparse (3 npts x nfree) operator: strains = Bs u, forces = Bs^t (w sigma)
        rows = (np.arange(self.npts * 3).reshape(self.ne, self.nq, 3)[..., None]
                + np.zeros(nb2, np.int64))
        cols = np.broadcast_to(self._redofs[:, None, None, :], rows.shape)
        keep = cols >= 0
        self._Bs = sp.csr_matrix((self.B[keep], (rows[keep], cols[keep])), shape=(3 * self.npts, self.nfree))
        self._BsT = self._Bs.T.tocsr()

        # sparsity pattern of the full tangent on the free dofs; slot of every element entry (-1: fixed dof)
        a, b = np.meshgrid(np.arange(nb2), np.arange(nb2), indexing="ij")
        ra, rb = self._redofs[:, a.ravel()], self._redofs[:, b.ravel()]
        keep = (ra >= 0) & (rb >= 0)  # (ne, nb2*nb2)
        keys = ra[keep] * self.nfree + rb[keep]
        uniq, slots = np.unique(keys, return_inverse=True)
        self._slot = np.full(keep.shape, -1, np.int64)
        self._slot[keep] = slots
        self._indices = (uniq % self.nfree).astype(np.int32)
        rows_u = uniq // self.nfree
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(rows_u, minlength=self.nfree))]).astype(np.int32)
        self.nnz = len(uniq)

    def restricted(self, elements: np.ndarray, dofs: np.ndarray) -> "PointOperators":
        """The operators of the body made of `elements` (indices into fe's elements) on the free dofs
        `dofs` (indices into fe's free numbering, increasing; every free dof of those elements among
        them), renumbered 0 .. len(dofs) - 1: points numbered element by element in the order of
        `elements`. What element removal and activation work with (a stage's active body)."""
        elements = np.asarray(elements, np.int64)
        dofs = np.asarray(dofs, np.int64)
        new = object.__new__(PointOperators)
        new.fe = self.fe
        new.elements = elements if self.elements is None else self.elements[elements]
        new.ne = len(elements)
        new.B, new.w = self.B[elements], self.w[elements]
        new.nq = self.nq
        new.npts = new.ne * new.nq
        new.nfree = len(dofs)
        relabel = -np.ones(self.nfree + 1, np.int64)  # (the last entry: a fixed dof, -1, stays -1)
        relabel[dofs] = np.arange(len(dofs))
        old = self._redofs[elements]
        new._redofs = relabel[old]
        if np.any((old >= 0) & (new._redofs < 0)):
            raise ValueError("restricted: a free dof of the elements is not among `dofs`")
        new._index()
        return new

    # ------------------------------------------------------------------ fields
    def element_dofs(self) -> np.ndarray:
        """(ne, 2nb) free-dof index of every element dof, -1 at fixed dofs."""
        return self._redofs

    def strain(self, u: np.ndarray) -> np.ndarray:
        """(exx, eyy, gxy) at every point, (npts, 3), or (npts, 3, k) for u of shape (nfree, k)."""
        e = self._Bs @ u
        return e.reshape((self.npts, 3) + u.shape[1:])

    def internal_force(self, stress: np.ndarray) -> np.ndarray:
        """int B^t sigma dV on the free dofs from stress (npts, 4|3[, k]): (sxx, syy, [szz,] sxy)."""
        if stress.shape[1] == 4:
            stress = stress[:, [0, 1, 3]]
        ws = stress * self.w.reshape(-1, *([1] * (stress.ndim - 1)))
        return self._BsT @ ws.reshape((3 * self.npts,) + stress.shape[2:])

    def element_matrices(self, C: np.ndarray, elements: np.ndarray | None = None) -> np.ndarray:
        """int_e B^t C B dV of the given elements (all by default), (n, nb2, nb2), from C
        (npts, 3|4, 3) of all points (the szz row is ignored)."""
        if C.shape[1] == 4:
            C = C[:, [0, 1, 3]]
        C = C.reshape(self.ne, self.nq, 3, 3)
        B, w = self.B, self.w
        if elements is not None:
            C, B, w = C[elements], B[elements], w[elements]
        CB = (C * w[..., None, None]) @ B  # (n, nq, 3, nb2)
        nb2 = B.shape[-1]
        return B.reshape(len(B), -1, nb2).transpose(0, 2, 1) @ CB.reshape(len(B), -1, nb2)

    def assemble(self, Ke: np.ndarray, elements: np.ndarray | None = None, base: np.ndarray | None = None):
        """Full CSR matrix on the free dofs: base (entries of a matrix of this pattern, zero by
        default) plus the element matrices Ke of the given elements (all by default)."""
        slot = self._slot if elements is None else self._slot[elements]
        keep = slot >= 0
        data = np.bincount(slot[keep], weights=Ke.reshape(slot.shape)[keep], minlength=self.nnz)
        if base is not None:
            data += base
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(self.nfree, self.nfree))

    def tangent(self, C: np.ndarray) -> sp.csr_matrix:
        """Full CSR matrix int B^t C B dV on the free dofs from C (npts, 3|4, 3)."""
        return self.assemble(self.element_matrices(C))

    def point_coordinates(self) -> np.ndarray:
        """(npts, 2) coordinates of the quadrature points."""
        N, _ = reference_basis(self.fe.element, self.fe._X)  # (nb, nq)
        tri = self.fe.tri if self.elements is None else self.fe.tri[self.elements]
        xy = np.einsum("enx,nq->eqx", self.fe.nodes[tri], N)
        return xy.reshape(-1, 2)

    def per_point(self, values, name: str = "value") -> np.ndarray:
        """A scalar, an (ne,) per-element or an (ne, nq) per-point array as (npts,)."""
        v = np.asarray(values)
        if v.ndim == 0:
            return np.full(self.npts, v)
        if v.shape == (self.ne,):
            return np.repeat(v, self.nq)
        if v.shape in ((self.ne, self.nq), (self.npts,)):
            return v.reshape(self.npts)
        raise ValueError(f"{name}: expected a scalar, ({self.ne},) per element or ({self.ne}, {self.nq}) "
                         f"per quadrature point, found shape {v.shape}")
