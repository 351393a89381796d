"""The amended case: the diagnosed case with the accepted extensions made part of its model, to go on
with (`geoback run amended.yaml` reproduces the final joint fit; forecasts and `design` work on it).

Each accepted extension is written in the engineer's form where the case schema has one, else as a
parameter:

- a layer boundary: a new layer in ``ground.layers`` (``<layer>_below`` at the boundary's depth, the
  upper layer's other properties, its modulus the estimate) and its modulus ``E[<layer>_below]``
  among the parameters;
- yielding: the layer made ``model: mohr-coulomb`` with the assumed phi' and psi and c' at its
  estimate, and ``c[layer]`` among the parameters;
- the release before the lining (``beta[stage]``): the stage's ``release`` set to the estimate, and
  the parameter; the lining's modulus: ``construction.lining.E``, and the parameter;
- a support before the full release (``support.py``): the construction section of the staged model
  (a release before the assumed lining, the rest after it), and ``beta[advance]``;
- every other extension (a modulus gradient ``Egrad[layer]``, anisotropy ``n[layer]``, ``K0grad``,
  ``beta``) and every instrument error (``B[I1]``, ``bias[I1]``, ``zoff[I1]``): its named parameter,
  which ``inference.parameters.resolve`` accepts in a case's ``parameters:``.

Every parameter starts from the final joint fit's estimate (the case's own initial values are in
the file's heading) with its bounds (a hypothesis' search range cut to the allowed range). Paths
of readings files are rewritten relative to the folder the amended case is written to; a results
folder (``output.dir``) is dropped, so that running it does not replace the diagnosed case's results.
"""
from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np
import yaml

AMENDED = "amended.yaml"
CHANGEABLE = ("model", "c", "phi", "psi", "tension", "nu", "K0")  # a layer's fields an extension may set


def _stress(v: float) -> str:
    """A modulus as the case writes it, exact enough to reproduce the fit (10 significant digits)."""
    return f"{v / 1e3:.12g} MPa"


def _value(v: float, unit: str):
    return _stress(v) if unit == "kPa" else float(v)


def _raw(loaded) -> dict:
    """The case as its file states it (units as written), or the model's data without a file."""
    if loaded.path is not None and Path(loaded.path).is_file():
        data = yaml.safe_load(Path(loaded.path).read_text(encoding="utf-8"))
        if isinstance(data, dict):
            return data
    return loaded.case.model_dump(mode="json", exclude_none=True)


def _relocated(path: str, source: Path, target: Path) -> str:
    """A path relative to the case file at `source` rewritten relative to the folder `target`."""
    p = Path(path)
    if p.is_absolute():
        return path
    full = (source / p).resolve()
    try:
        return os.path.relpath(full, target.resolve()).replace(os.sep, "/")
    except ValueError:  # another drive (Windows): keep it absolute
        return str(full)


def amended_case(d, folder: Path) -> tuple[dict, str]:
    """(the amended case's data, the heading of the file) for a diagnosis `d` with accepted
    extensions, to be written in `folder`."""
    loaded = d.loaded
    data = copy.deepcopy(_raw(loaded))
    final_case = d.final_misfit.simulation.loaded.case
    params = d.final.parameters
    estimate = dict(zip(params.names, map(float, d.final_fit.p)))
    source = loaded.folder
    # the ground: layers the accepted boundaries added, with their depth and modulus
    raw_layers = data["ground"]["layers"]
    by_name = {ly["name"]: ly for ly in raw_layers}
    before = {ly.name: ly for ly in loaded.case.ground.layers}
    layers = []
    for ly in final_case.ground.layers:
        if ly.name in by_name:  # as written, with what an extension changed (yielding: mohr-coulomb, c', phi', psi)
            layer = dict(by_name[ly.name])
            for key in CHANGEABLE:
                now, was = getattr(ly, key), getattr(before[ly.name], key, None) if ly.name in before else None
                if now != was and now is not None:
                    value = estimate.get(f"{key}[{ly.name}]", now)
                    layer[key] = float(value) if isinstance(value, (int, float)) else value
            layers.append(layer)
            continue
        upper = next((u for u in raw_layers if ly.name.startswith(f"{u['name']}_")), None)
        new = {k: v for k, v in (upper or {}).items() if k not in ("name", "top", "E")}
        E = estimate.get(f"E[{ly.name}]", float(ly.E))
        layers.append({"name": ly.name, "top": float(ly.top), "E": _stress(E), **new})
    data["ground"]["layers"] = layers
    # the construction plan: releases and the lining's modulus at their estimates
    construction = data.get("construction")
    if not construction and final_case.construction is not None:  # an accepted support (support.py)
        construction = data["construction"] = final_case.construction.model_dump(mode="json", exclude_none=True)
    if construction:
        for stage in construction.get("stages", []):
            name = f"beta[{stage.get('name')}]"
            if name in estimate and stage.get("release") is not None:
                stage["release"] = estimate[name]
        lining = construction.get("lining")
        if lining:
            name = f"E[{lining.get('name', 'lining')}]"
            if name in estimate:
                lining["E"] = _stress(estimate[name])
    # the parameters: the case's (canonical names: a split layer makes 'E' ambiguous), then the accepted ones'
    raw_params = list(data.get("parameters") or [])
    n0 = d.baseline.parameters.n
    out = []
    for i, name in enumerate(params.names):
        spec = dict(raw_params[i]) if i < n0 and i < len(raw_params) else {}
        unit = params.units[i]
        spec["name"] = name
        spec["initial"] = _value(estimate[name], unit)
        if i >= n0:
            spec["bounds"] = [_value(float(params.lower[i]), unit), _value(float(params.upper[i]), unit)]
            if params.log[i]:
                spec["log"] = True
        out.append(spec)
    data["parameters"] = out
    # readings files found from where the amended case is written; readings given in memory
    # (Analysis.with_readings) written out, so that the amended case holds what was diagnosed
    inline = _readings_given_in_memory(d)
    for ins in data.get("instruments", []):
        if not isinstance(ins, dict):
            continue
        if ins.get("name") in inline:
            for key in ("readings_file", "readings_unit"):
                ins.pop(key, None)
            if "reading_type" in ins:
                ins["reading_type"] = "displacement"
            ins["readings"] = inline[ins["name"]]
            since = next((b.since for b in d.final.data.blocks if b.name == ins["name"]), None)
            for key in ("baseline", "columns", "ignore_columns", "surveys"):  # what the file said: done
                ins.pop(key, None)
            if since is not None:  # the readings are increments since the installation
                ins["installed_after"] = since
        elif ins.get("readings_file"):
            ins["readings_file"] = _relocated(ins["readings_file"], source, Path(folder))
    output = data.get("output")
    if isinstance(output, dict):
        output.pop("dir", None)
        if not output:
            data.pop("output")
    data["name"] = f"{final_case.name}-amended"
    initial = ", ".join(f"{n} = {_shown_initial(v, u)}" for n, v, u in
                        zip(d.baseline.parameters.names, d.baseline.parameters.initial, d.baseline.parameters.units))
    added = "; ".join(s.hypothesis.title for s in d.accepted)
    tentative = [s.hypothesis.title for s in d.accepted if not s.determined]
    source_name = Path(loaded.path).name if loaded.path is not None else loaded.case.name
    heading = [f"Amended by `geoback diagnose` from {source_name}: {added}.",
               "The accepted extensions are part of the model; every parameter starts from the diagnosis' final",
               f"joint fit (the case's initial values were: {initial}).",
               f"`geoback run {AMENDED}` reproduces that fit; forecasts and `geoback design` work on it."]
    if inline:
        heading.append("The readings diagnosed were given in memory, not those of the case's files: they are "
                       "written here (SI units, displacements).")
    if tentative:
        heading.append(f"TENTATIVE: the readings do not determine {'; '.join(tentative)} (where and which way, "
                       "not how much).")
    if d.final_fit.status != "converged":
        heading.append(f"The final joint fit did not converge ({d.final_fit.reason}).")
    return data, "".join(f"# {line}\n" for line in heading)


def _readings_given_in_memory(d) -> dict:
    """{instrument: readings} when the diagnosed readings are not those the case's files and
    entries give (``Analysis.with_readings``); empty when they are."""
    from geoback.observation.readings import measured_values

    data = d.final.data
    try:
        from_case = measured_values(d.loaded, list(data.blocks))
    except Exception:  # noqa: BLE001 - the case's own readings cannot be read back: write the diagnosed ones
        from_case = None
    if from_case is not None and np.array_equal(from_case, data.measured):
        return {}
    staged = d.loaded.case.construction is not None
    out: dict = {}
    for block, rows in data.block_rows():
        values = [float(v) for v in data.measured[rows]]
        if staged:
            if block.stage in out.get(block.name, {}):
                from geoback.errors import GeobackError

                raise GeobackError(f"amended.yaml cannot hold the readings of '{block.name}' given in memory: it has "
                                   f"several surveys at stage '{block.stage}', and inline readings hold one a stage "
                                   f"(give them in a readings file with a date column)")
            out.setdefault(block.name, {})[block.stage] = values
        else:
            out[block.name] = values
    return out


def _shown_initial(v: float, unit: str) -> str:
    return f"{v / 1e3:g} MPa" if unit == "kPa" else f"{v:g}" + ("" if unit in ("-", "") else f" {unit}")


def amended_text(d, folder: Path) -> str:
    """amended.yaml as text, checked by the case's own loader (schema and physical checks)."""
    from geoback.case.loading import case_from_data

    data, heading = amended_case(d, folder)
    case_from_data(data, file=AMENDED)  # never write a case `run` would refuse
    return heading + yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=110, default_flow_style=None)
