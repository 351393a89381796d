"""The mesh cache survives faults: an entry that is truncated, empty, corrupt or inconsistent is
rebuilt with one notice on stderr, and the run goes on; a cache that cannot be written is skipped."""
from __future__ import annotations

import copy
import io
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

import geoback.physics.mesh
from geoback.case.loading import case_from_data
from geoback.case.meshsize import mesh_inputs
from geoback.physics.mesh import build_mesh, mesh_key
from measure import run_cli

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("GEOBACK_CACHE", str(folder))
    return folder


def coarse_case():
    data = yaml.safe_load(PAPER.read_text())
    data["mesh"] = {"size_tunnel": 0.75, "size_far": 6.0}
    return case_from_data(data, {}, file="coarse.yaml")


def entry_path(case) -> Path:
    return geoback.physics.mesh.cache_dir() / "meshes" / f"{mesh_key(mesh_inputs(case))}.npz"


def _arrays(path: Path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def _resave(path: Path, arrays: dict, keep_checksum: bool = False) -> None:
    """Write arrays back, with a checksum recomputed for them (an entry consistent as a file,
    inconsistent as a mesh) unless keep_checksum."""
    if not keep_checksum:
        arrays = dict(arrays, checksum=np.array(geoback.physics.mesh._checksum(arrays)))
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _flip_payload_byte(path: Path) -> None:
    """Corrupt a byte inside the stored node coordinates (the zip's own structure stays valid)."""
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as z:
        info = z.getinfo("nodes.npy")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 200
    data[start] ^= 0xFF
    path.write_bytes(bytes(data))


def _damage(path: Path, how: str) -> None:
    if how == "truncated":
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "garbage":
        path.write_bytes(os.urandom(4096))
    elif how == "flipped byte":
        _flip_payload_byte(path)
    elif how == "directory":
        path.unlink()
        path.mkdir()
    else:
        a = _arrays(path)
        if how == "missing array":
            del a["tunnel_edges"]
            _resave(path, a, keep_checksum=True)
            return
        if how == "node index out of range":
            a["triangles"] = a["triangles"].copy()
            a["triangles"][5, 2] = len(a["nodes"]) + 7
        elif how == "negative index":
            a["triangles"] = a["triangles"].copy()
            a["triangles"][0, 0] = -1
        elif how == "wrong shape":
            a["triangles"] = a["triangles"][:, :3].copy()  # linear triangles for a quadratic case
        elif how == "region out of range":
            a["region"] = a["region"].copy()
            a["region"][3] = 4
        elif how == "tunnel edges out of range":
            a["tunnel_edges"] = a["tunnel_edges"].copy()
            a["tunnel_edges"][0, 0] = 10 ** 9
        elif how == "fewer regions than triangles":
            a["region"] = a["region"][:-1]
        elif how == "other layer names":
            a["region_names"] = np.array(["sand"])
        elif how == "stale checksum":
            a["nodes"] = a["nodes"] * 1.001  # consistent shapes, wrong numbers
            _resave(path, a, keep_checksum=True)
            return
        elif how == "no checksum":
            del a["checksum"]
            _resave(path, a, keep_checksum=True)
            return
        elif how == "object array":
            a["region_names"] = np.array([{"clay": 1}], dtype=object)
            with open(path, "wb") as fh:
                np.savez(fh, **a)
            return
        _resave(path, a)


DAMAGES = ["truncated", "empty", "garbage", "flipped byte", "directory", "missing array",
           "node index out of range", "negative index", "wrong shape", "region out of range",
           "tunnel edges out of range", "fewer regions than triangles", "other layer names",
           "stale checksum", "no checksum", "object array"]


@pytest.mark.parametrize("how", DAMAGES)
def test_damaged_entry_is_rebuilt_with_a_notice(how, cache, capsys):
    case = coarse_case()
    fresh = build_mesh(case)
    path = entry_path(case)
    assert path.is_file()
    capsys.readouterr()
    _damage(path, how)
    calls = geoback.physics.mesh.GMSH_CALLS
    mesh = build_mesh(case)
    assert geoback.physics.mesh.GMSH_CALLS == calls + 1, "the damaged entry was used"
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    if how == "directory":  # cannot be replaced: rebuilt, and the cache write skipped, each said once
        assert len(lines) == 2 and lines[0].startswith("notice: cached mesh") and "could not write" in lines[1], err
    else:
        assert len(lines) == 1 and lines[0].startswith(f"notice: cached mesh {path} is damaged ("), err
        assert lines[0].endswith("; meshing again"), err
    for name in ("nodes", "triangles", "region", "tunnel_edges"):
        assert np.array_equal(getattr(mesh, name), getattr(fresh, name)), name
    if how != "directory":  # the entry was rewritten and is used from now on, silently
        build_mesh(case)
        assert geoback.physics.mesh.GMSH_CALLS == calls + 1
        assert capsys.readouterr().err == ""


def test_unwritable_cache_is_skipped(tmp_path, monkeypatch, capsys):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    monkeypatch.setenv("GEOBACK_CACHE", str(blocker))
    mesh = build_mesh(coarse_case())
    assert len(mesh.triangles) > 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("notice: could not write the mesh cache"), err


def test_stale_temporary_files_are_removed(cache, monkeypatch):
    case = coarse_case()
    build_mesh(case)
    folder = entry_path(case).parent
    stale = folder / ".abc.123.tmp.npz"
    fresh = folder / ".def.456.tmp.npz"
    stale.write_bytes(b"half")
    fresh.write_bytes(b"being written")
    old = os.path.getmtime(stale) - 2 * geoback.physics.mesh._STALE_TMP_SECONDS
    os.utime(stale, (old, old))
    other = copy.deepcopy(yaml.safe_load(PAPER.read_text()))
    other["mesh"] = {"size_tunnel": 0.7, "size_far": 6.0}
    build_mesh(case_from_data(other, {}, file="other.yaml"))  # writing an entry tidies the folder
    assert not stale.exists() and fresh.exists()


@pytest.mark.parametrize("how", ["truncated", "empty", "node index out of range"])
def test_commands_survive_a_damaged_cache(how, tmp_path):
    """Through the CLI: validate and run both succeed after damage, with a one-line notice."""
    env = dict(os.environ, GEOBACK_CACHE=str(tmp_path / "cache"))
    env.pop("GEOBACK_DEBUG", None)
    first = run_cli(["validate", PAPER], tmp_path, env=env)
    assert first.returncode == 0, first.stderr
    (entry,) = (tmp_path / "cache" / "meshes").glob("*.npz")
    for command in (["validate", PAPER], ["run", PAPER, "-q", "--out", tmp_path / "out"]):
        _damage(entry, how)
        proc = run_cli(command, tmp_path, env=env)
        assert proc.returncode == 0, proc.stderr
        notices = [line for line in proc.stderr.splitlines() if line.startswith("notice:")]
        assert len(notices) == 1 and "is damaged" in notices[0], proc.stderr
        assert "Traceback" not in proc.stderr
