"""Discretisation error of the computed readings, against the readings' own errors.

The readings are computed again at the estimate on a mesh `refine` times finer (the same case,
instruments and named values); the difference d = x_fine - x estimates the fitting mesh's error
on each reading (most of it: the finer mesh's own error is smaller by about refine^2 for P2
elements). It is compared with each reading's standard deviation: above WARN = 0.3 sigma the
estimate may be biased by the mesh, and the case can either be meshed finer or have the error
added to C_x as an independent error of variance d^2 (``fit: {mesh_error: include}``). The finer
mesh's run is a probe (``Simulation.probing``): with Mohr-Coulomb ground its Newton iterations stop at
``plastic.PROBE_TOL``, which moves d by some 1e-9 sigma on ``cases/plastic-tunnel.yaml``.

The check is skipped, and says why, rather than lose the fit: when the finer mesh is too large
(``MAX_FINE_DOFS``; for staged and Mohr-Coulomb ground, more memory than the size limit allows:
``meshsize.check_fits``), when the time limit has passed (``geoback.case.budget``), or when the model has
no solution on the finer mesh (a Mohr-Coulomb run that does not converge there: the fit at the
estimate stands; it was lost with exit code 2 before).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WARN = 0.3  # largest |d| / sigma tolerated without a warning
MAX_FINE_DOFS = 400_000  # a check that would mesh more is skipped (said in the result)


@dataclass(frozen=True)
class MeshError:
    """d = x_fine - x at the estimate, per reading, in metres (or the readings' units) and in sigma."""

    refine: float
    dofs: int
    fine_dofs: int
    difference: np.ndarray  # (m,)
    in_sigma: np.ndarray  # (m,) |d| / sqrt(diag C_x)
    whitened_norm: float  # ||L^-1 d|| with the case's full C_x
    labels: tuple
    skipped: str = ""  # why the check was not made (then the arrays are empty)

    @property
    def worst(self) -> int:
        return int(np.argmax(self.in_sigma))

    @property
    def max_sigma(self) -> float:
        return float(self.in_sigma.max()) if len(self.in_sigma) else 0.0

    def text(self) -> str:
        if self.skipped:
            return f"discretisation error not checked: {self.skipped}"
        lab = self.labels[self.worst]
        staged = len({b.stage for b in self.labels}) > 1
        where = f"{lab.instrument}:{lab.station}" + (f" at {lab.stage}" if staged and lab.stage else "")
        return (f"discretisation error of the readings at the estimate (the mesh {self.refine:g} times finer, "
                f"{self.fine_dofs:,} DOFs): at most {self.max_sigma:.2g} sigma ({where}, "
                f"{abs(self.difference[self.worst]) * 1e3:.2g} mm), whitened norm {self.whitened_norm:.2g}")

    def as_dict(self) -> dict:
        if self.skipped:
            return {"checked": False, "reason": self.skipped}
        return {"checked": True, "refine": self.refine, "fine_dofs": self.fine_dofs, "max_sigma": self.max_sigma,
                "whitened_norm": self.whitened_norm, "worst_reading": self.worst,
                "difference": self.difference, "in_sigma": self.in_sigma}


def discretisation_error(analysis, misfit, p: np.ndarray, refine: float = 2.0) -> MeshError:
    """The readings at p on a mesh `refine` times finer than the analysis' (see the module docstring)."""
    from geoback.case import budget
    from geoback.case.meshsize import Work, check_fits, estimate, mesh_inputs, refined_case
    from geoback.errors import ForwardFailure, TimeLimit
    from geoback.physics.factory import make_simulation

    sim = analysis.simulation
    fine_case = refined_case(analysis.case, refine)
    fine_dofs = int(estimate(mesh_inputs(fine_case)).dofs)
    labels = tuple(misfit.data.labels)

    def skipped(why: str) -> MeshError:
        return MeshError(refine, sim.dofs, fine_dofs, np.zeros(0), np.zeros(0), 0.0, labels, why)

    work = Work.of(analysis.case)
    if fine_dofs > MAX_FINE_DOFS:
        return skipped(f"the mesh {refine:g} times finer would have about {fine_dofs:,} DOFs (more than {MAX_FINE_DOFS:,})")
    if work.physics != "elastic" and check_fits(work, fine_dofs, analysis.case.mesh.order):
        return skipped(check_fits(work, fine_dofs, analysis.case.mesh.order))
    if budget.expired("the discretisation-error check"):
        return skipped(f"{budget.describe_limit()} was reached")
    values = misfit.values(p)
    fine = None
    budget.say(f"discretisation error: the readings at the estimate on the mesh {refine:g} times finer "
               f"(about {fine_dofs:,} DOFs)")
    try:
        fine = make_simulation(analysis.loaded.with_case(fine_case), blocks=list(sim.survey.blocks),
                               backend=getattr(sim, "backend", None))
        with fine.probing():  # (readings only, against 0.3 sigma: a probe's Newton tolerance)
            x_fine = fine.predict(values).x
        d = x_fine - sim.predict(values).x
    except ForwardFailure as exc:  # the finer model has no solution there (Mohr-Coulomb): the fit is kept
        return skipped(f"the model could not be solved on the mesh {refine:g} times finer ({exc})")
    except TimeLimit:
        return skipped(f"{budget.describe_limit()} was reached in its run on the mesh {refine:g} times finer")
    finally:
        if fine is not None:
            fine.release()
    sigma = np.sqrt(np.diag(misfit.data.covariance))
    full = misfit if misfit.weighting == "full" else misfit.with_weighting("full")
    wn = float(np.linalg.norm(full.whiten(d)))
    return MeshError(refine, sim.dofs, fine.dofs, d, np.abs(d) / sigma, wn, labels)
