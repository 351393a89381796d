"""`geoback validate` after the schema and physics: instruments, readings and parameters checked by
building the forward problem, within a few seconds and a few hundred MB whatever the mesh.

A mesh estimated at most ``VALIDATE_MESH_DOFS`` is built as it will be used: gmsh runs on the real sizes and the
finite-element model is assembled. A larger mesh is not (building it would take
longer than validate may: up to a minute and 2 GB at the default size limit,
``geoback.case.meshsize.DEFAULT_MAX_DOFS``):
the same checks then run on a coarse stand-in mesh of the same geometry (the checks of
instruments, readings and parameters are geometric and do not depend on the element size), and
the result says so.
"""
from __future__ import annotations

from geoback.case.loading import LoadedCase, MeshSettings
from geoback.case.meshsize import describe_bytes as _bytes

VALIDATE_MESH_DOFS = 50_000  # measured cold (gmsh included): 33 k DOFs 2.2 s 260 MB, 73 k DOFs 4.7 s 440 MB


def stand_in_case(case):
    """The case with the default (coarse) mesh sizes: same geometry, layers and element order."""
    return case.model_copy(update={"mesh": MeshSettings(order=case.mesh.order, growth=max(case.mesh.growth, 0.25))})


def check_case(loaded: LoadedCase) -> str:
    """Build what `run` builds (or its coarse stand-in); return the verdict: one line, then how every
    instrument's readings were matched, the instruments without readings, and warnings. Raises
    GeobackError (located when it is the case's fault); a CaseError carries every problem of the
    readings found (``CaseError.problems``)."""
    from geoback.inference.identification import prepare
    from geoback.case.meshsize import Work, estimate, mesh_inputs
    from geoback.observation.readings import readings_report, require_readings

    case = loaded.case
    report = readings_report(loaded)  # every readings problem at once, before meshing
    require_readings(loaded, report)  # what `run` refuses before fitting, validate refuses too (issue 23)
    work = Work.of(case)
    est = estimate(mesh_inputs(case), work)
    name = loaded.path if loaded.path is not None else case.name
    if est.dofs <= VALIDATE_MESH_DOFS:
        analysis = prepare(loaded)
        mesh_text = f"{analysis.simulation.dofs} dofs"
    else:
        analysis = prepare(loaded.with_case(stand_in_case(case)))
        mesh_text = (f"mesh {est.describe()} to run, not built by validate: instruments, readings and "
                     f"parameters checked on a coarser mesh of the same geometry")
    warned = "".join(f"\nwarning: [{c.code}] {c.message}" for c in analysis.notices)
    read = sum(n.count for n in report.notes)
    matched = "".join(f"\n  {n.text()}" for n in report.notes)
    built = ""
    if hasattr(case.geometry, "openings"):  # what each stage does, the defaults said
        from geoback.case.sequence import Sequence

        built = "\nconstruction:" + "".join(f"\n  {line}" for line in Sequence.of(case).describe())
    return (f"{name}: valid ({len(case.instruments)} instruments, {read} readings, "
            f"{len(case.parameters)} parameters, {mesh_text}){matched}{built}{warned}\n{cost_text(est)}")


def cost_text(est) -> str:
    """What `run` will cost: 'run: ~210 MB at most; Mohr-Coulomb ground: up to 10 load increments ...'."""
    work = est.work
    check = ""
    if est.fine_dofs is not None:
        check = (f" (its discretisation-error check skipped: {est.check_skipped})" if est.check_skipped else
                 f" (with its discretisation-error check on a mesh twice as fine, about {est.fine_dofs:,.0f} DOFs)")
    return f"cost of `geoback run`: ~{_bytes(est.run_bytes)} of memory at most{check}; {work.describe(est.dofs)}"
