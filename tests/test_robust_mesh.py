"""Bounded work before meshing: the mesh size is estimated before gmsh runs, cases beyond the
limit are refused with the estimated DOFs and memory unless --allow-large, and `validate` stays
within 5 s and 500 MB for whatever it accepts."""
from __future__ import annotations

import copy
import os
import re
import sys
from pathlib import Path

import pytest
import yaml

import geoback.physics.mesh
from geoback.case import meshsize
from geoback.case.loading import case_from_data, load_case
from geoback.errors import CaseError, GeobackError
from geoback.case.meshsize import mesh_inputs
from geoback.physics.mesh import _run_gmsh, build_mesh
from geoback.commands.validation import VALIDATE_MESH_DOFS
from measure import run_cli

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
BASE = yaml.safe_load(PAPER.read_text())
sys.path.insert(0, str(ROOT / "benchmarks"))
from mesh_estimate import FACTOR, variants  # noqa: E402

SMALL = [(label, data) for label, data in variants() if "elements" not in label]
LARGE = [(label, data) for label, data in variants() if "elements" in label]


def _ratios(data: dict) -> tuple[float, float]:
    case = case_from_data(copy.deepcopy(data), {}, file="x", allow_large=True)
    inputs = mesh_inputs(case)
    est = meshsize.estimate(inputs)
    mesh = _run_gmsh(inputs, "estimate-test")
    return est.elements / len(mesh.triangles), est.dofs / (2 * len(mesh.nodes))


@pytest.mark.parametrize("label, data", SMALL, ids=[v[0] for v in SMALL])
def test_estimate_within_stated_factor(label, data):
    """Elements and DOFs estimated within FACTOR of gmsh's, across geometries, sizes, growth,
    layers, instrument refinement and element order."""
    for ratio in _ratios(data):
        assert 1 / FACTOR <= ratio <= FACTOR, f"{label}: estimate/gmsh = {ratio:.3f}"


@pytest.mark.slow
@pytest.mark.parametrize("label, data", LARGE, ids=[v[0] for v in LARGE])
def test_estimate_within_stated_factor_large(label, data):
    for ratio in _ratios(data):
        assert 1 / FACTOR <= ratio <= FACTOR, f"{label}: estimate/gmsh = {ratio:.3f}"


def _case(tmp_path: Path, name: str, **mesh) -> Path:
    data = copy.deepcopy(BASE)
    data["mesh"] = mesh
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_refusal_states_dofs_and_memory_before_gmsh(tmp_path, monkeypatch):
    """The issue's case: ~1 M elements, accepted silently before. Now refused at load, located at
    the mesh setting responsible, with DOFs and memory, without running gmsh."""
    path = _case(tmp_path, "big.yaml", size_tunnel=0.01, size_far=0.05)
    calls = geoback.physics.mesh.GMSH_CALLS
    with pytest.raises(CaseError) as info:
        load_case(path)
    message = str(info.value)
    assert re.match(rf"^{re.escape(str(path))}:\d+:\d+: mesh\.size_far: expected mesh sizes giving at most "
                    r"500,000 DOFs \(~1\.8 GB to run\), found sizes giving about [\d.]+ M DOFs, ~\d+ GB "
                    r"\(about [\d.,]+ (M )?elements, mostly from size_far 0\.05\); coarsen the mesh "
                    r"\(larger mesh sizes\) or pass --allow-large$", message), message
    assert geoback.physics.mesh.GMSH_CALLS == calls
    loaded = load_case(path, allow_large=True)  # lifted; nothing meshed yet
    assert loaded.allow_large and geoback.physics.mesh.GMSH_CALLS == calls
    with pytest.raises(GeobackError, match="pass --allow-large"):
        build_mesh(loaded.case)  # the library's own guard, for cases made in code
    assert geoback.physics.mesh.GMSH_CALLS == calls


def test_hard_limit_even_with_allow_large(tmp_path):
    path = _case(tmp_path, "absurd.yaml", size_tunnel=0.001, size_far=0.003)
    with pytest.raises(CaseError, match=r"beyond what geoback can solve"):
        load_case(path, allow_large=True)


def test_limit_follows_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("GEOBACK_MAX_DOFS", "1000")
    with pytest.raises(CaseError, match=r"at most 1,000 DOFs"):
        load_case(PAPER)
    monkeypatch.setenv("GEOBACK_MAX_DOFS", "lots")
    with pytest.raises(GeobackError, match="GEOBACK_MAX_DOFS"):
        load_case(PAPER)


@pytest.fixture(scope="module")
def small_limit_env(tmp_path_factory):
    env = dict(os.environ)
    env["GEOBACK_MAX_DOFS"] = "1000"  # the paper case (2,252 DOFs) is then "large"
    env["GEOBACK_CACHE"] = str(tmp_path_factory.mktemp("cache"))
    env.pop("GEOBACK_DEBUG", None)
    return env


COMMANDS = [["validate"], ["mesh", "--out", "{tmp}/m"], ["simulate", "--out", "{tmp}/s"],
            ["run", "-q", "--out", "{tmp}/r"], ["diagnose", "-q", "--no-plots", "--out", "{tmp}/d"]]


@pytest.mark.parametrize("command", COMMANDS, ids=[c[0] for c in COMMANDS])
def test_every_command_refuses_and_allow_large_lifts(command, tmp_path, small_limit_env):
    args = [a.format(tmp=tmp_path) for a in command]
    refused = run_cli(args[:1] + [PAPER] + args[1:], tmp_path, env=small_limit_env)
    assert refused.returncode == 2, refused.stderr
    assert "Traceback" not in refused.stderr
    assert "DOFs" in refused.stderr and "pass --allow-large" in refused.stderr, refused.stderr
    assert refused.stderr.startswith(f"error: {PAPER}:"), refused.stderr
    assert not list(tmp_path.glob("*/")), "a refused command wrote results"
    allowed = run_cli(args[:1] + [PAPER, "--allow-large"] + args[1:], tmp_path, env=small_limit_env)
    assert allowed.returncode in (0, 1), allowed.stderr  # run/diagnose: 1 = not converged / not adequate
    assert "Traceback" not in allowed.stderr


def test_batch_refuses_and_allow_large_lifts(tmp_path, small_limit_env):
    refused = run_cli(["batch", PAPER, "--out", tmp_path / "b", "--workers", "1"], tmp_path, env=small_limit_env)
    assert refused.returncode == 1 and "pass --allow-large" in refused.stderr, refused.stderr
    allowed = run_cli(["batch", PAPER, "--out", tmp_path / "b2", "--workers", "1", "--allow-large"], tmp_path,
                      env=small_limit_env)
    assert allowed.returncode == 0, allowed.stderr


def test_refine_is_guarded_where_meshing_happens(tmp_path, small_limit_env):
    """`simulate --refine` makes a finer mesh than the case's: refused by build_mesh itself."""
    env = dict(small_limit_env, GEOBACK_MAX_DOFS="5000")
    proc = run_cli(["simulate", PAPER, "--refine", "3", "--readings-out", tmp_path / "r.csv"], tmp_path, env=env)
    assert proc.returncode == 2 and "pass --allow-large" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("mesh", [dict(size_tunnel=0.4, size_far=4.0),  # the paper case
                                  dict(size_tunnel=0.07, size_far=0.5),  # just under VALIDATE_MESH_DOFS
                                  dict(size_tunnel=0.04, size_far=0.16)],  # just under the default limit
                         ids=["paper", "built", "stand-in"])
def test_validate_within_500_MB(mesh, tmp_path):
    """Cold cache, fresh interpreter: whatever validate accepts by default costs at most 500 MB
    (meshes above VALIDATE_MESH_DOFS are checked on a coarse stand-in, not built; its time is
    measured by benchmarks/command_times.py, not asserted here)."""
    path = _case(tmp_path, "case.yaml", **mesh)
    est = meshsize.estimate(mesh_inputs(load_case(path).case))
    assert est.dofs <= meshsize.max_dofs()
    env = dict(os.environ, GEOBACK_CACHE=str(tmp_path / "cache"))
    proc = run_cli(["validate", path], tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    assert not proc.peak_bytes > 500e6, f"{proc.peak_bytes / 1e6:.0f} MB"
    built = est.dofs <= VALIDATE_MESH_DOFS
    assert ("not built by validate" in proc.stdout) != built, proc.stdout
