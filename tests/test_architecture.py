"""The house: rooms by concept, dependencies pointing one way, no cycles, no private names across modules.

The layer order (commands -> reports -> worth -> diagnosis -> inference -> physics -> observation -> case ->
foundation) is an import-linter contract in ``pyproject.toml``; these tests run it and check what a
layer contract cannot: cycles between modules of one room, private names taken across modules, and the
public API (``docs/architecture.md``).
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import grimp
import pytest

pytestmark = pytest.mark.quick

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "geoback"


def test_layers_point_one_way():
    """import-linter's layer contract over the whole package (the rooms' order), as `lint-imports` runs it."""
    run = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command;"
                          " sys.exit(lint_imports_command())"], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "1 kept, 0 broken" in run.stdout


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), lazy imports included."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    modules = sorted(graph.modules)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.find_modules_directly_imported_by(v)):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in modules:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    """No module imports, directly or through others, a module that imports it back (package faces
    that only hand names on are modules too)."""
    graph = grimp.build_graph("geoback", cache_dir=None)
    assert _cycles(graph) == []
    # the detector itself: one import back from the case to the commands closes a loop it must find
    graph.add_import(importer="geoback.case.loading", imported="geoback.commands.cli")
    assert any("geoback.commands.cli" in c and "geoback.case.loading" in c for c in _cycles(graph))


def _private_imports() -> list[str]:
    found = []
    for path in sorted(SRC.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("geoback"):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.module}.{alias.name}")
    return found


def test_no_private_name_imported_across_modules():
    assert _private_imports() == []


def test_every_room_is_a_package_with_a_docstring():
    rooms = sorted(p.parent.name for p in SRC.glob("*/__init__.py"))
    assert rooms == ["case", "commands", "diagnosis", "inference", "observation", "physics", "reports", "worth"]
    for room in rooms:
        doc = ast.get_docstring(ast.parse((SRC / room / "__init__.py").read_text()))
        assert doc and len(doc) > 40, room
    loose = sorted(p.name for p in SRC.glob("*.py"))
    assert loose == ["__init__.py", "errors.py", "outputs.py", "units.py"]  # the foundation, below every room


def test_public_api_visible_to_dir_and_tab_completion():
    import geoback

    names = dir(geoback)
    for name in ("load_case", "prepare", "identify", "diagnose", "forecast", "design", "fit_report"):
        assert name in names
        assert callable(getattr(geoback, name))
    with pytest.raises(AttributeError):
        geoback.no_such_thing  # noqa: B018


def test_fit_report_of_the_public_api(paper_case_path):
    import geoback

    text = geoback.fit_report(geoback.identify(geoback.load_case(paper_case_path)))
    assert "E[clay]" in text and "K0" in text


def _calls(names: set[str]) -> dict[str, list[str]]:
    """Files of src (the physics room aside: it inverts element Jacobians and factorises stiffness
    matrices, never an information matrix or a reading's covariance) calling a function named in
    `names` (np.linalg.inv(...), sla.cho_solve(...), inv(...)), with the lines."""
    found: dict[str, list[str]] = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("src/geoback/physics/"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
                if name in names:
                    found.setdefault(rel, []).append(f"{node.lineno}: {name}")
    return found


def test_eqn_55_is_solved_in_one_place():
    """C_p = (A'^t A' + C_p0^-1)^-1 (eqn 55) and every posterior made from it (predictions, a
    candidate's data worth, the prior -> posterior table, replicates) come from
    inference/linear_analysis.py: nothing else in src inverts a matrix."""
    found = _calls({"inv", "pinv", "cho_solve", "cho_factor", "lu_factor", "lu_solve"})
    assert set(found) <= {"src/geoback/inference/linear_analysis.py"}, found
    # and the detector finds an inversion where there is one (the physics' element Jacobians)
    assert "inv" in (SRC / "physics" / "fem.py").read_text()
    users = ("inference/reliability.py", "inference/replicates.py", "inference/identifiability.py",
             "worth/design.py", "worth/forecast.py")
    for module in users:
        text = (SRC / module).read_text()
        assert "LinearAnalysis" in text or "posterior(" in text or ".linear" in text, module


def test_readings_are_whitened_and_noise_drawn_only_by_the_seam():
    """Factors of a covariance and triangular solves with them live in the seam (inference/misfit.py:
    the survey's L, a candidate block's L_c, noise L z) and where cholesky_factor is defined and a
    case's C_x is validated (case/); besides them only the LM step factorises its damped normal
    matrix (inference/estimate.py) and the forecast's sampling check factorises C_p to draw parameter
    sets (worth/forecast.py). Random normal draws: the readings' noise (seam) and those parameter sets."""
    factor_sites = {"src/geoback/case/covariance.py", "src/geoback/case/checks.py", "src/geoback/inference/misfit.py",
                    "src/geoback/inference/estimate.py", "src/geoback/worth/forecast.py"}
    found = _calls({"cholesky", "cholesky_factor", "solve_triangular", "dtrtrs", "_trtrs"})
    assert set(found) <= factor_sites, found
    assert set(found) >= {"src/geoback/inference/misfit.py"}
    noise = _calls({"standard_normal", "normal", "multivariate_normal"})
    assert set(noise) <= {"src/geoback/inference/misfit.py", "src/geoback/worth/forecast.py"}, noise
