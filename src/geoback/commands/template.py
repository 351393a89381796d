"""`geoback init`: a commented template case that validates and runs as it is.

The template is the paper's synthetic tunnel (Ledesma, Gens & Alonso 1996, Part I) with a
line of surface settlement points added. Its readings were simulated by geoback with
E = 10 MPa, K0 = 1 on a mesh twice as fine as the fitting mesh (settlements rounded to 0.1 mm),
so `geoback run case.yaml` recovers E ~ 10 MPa and K0 ~ 1 from the paper's starting values.
"""
from __future__ import annotations

import os
from pathlib import Path

from geoback.errors import GeobackError
from geoback.outputs import write_atomic

TEMPLATE = """\
# geoback case file (YAML).  Check it with `geoback validate case.yaml`, identify the
# parameters with `geoback run case.yaml`; `geoback schema` prints the full JSON Schema.
#
# Units are SI throughout: lengths in m, stresses and moduli in kPa (a string such as
# "10 MPa" is accepted for a stress or a modulus), unit weights in kN/m3, angles in rad
# (except a mohr-coulomb layer's friction and dilation angles, in degrees).
# Coordinates are those of the half-model: x = 0 on the tunnel's symmetry axis, x > 0
# towards the far side, y = 0 at the ground surface and y upwards (so depth = -y).
#
# This template is the synthetic example of Ledesma, Gens & Alonso (1996), Part I (a shallow
# circular tunnel excavated in one step in undrained elastic ground) with a line of surface
# settlement points added.  The readings were simulated with E = 10 MPa, K0 = 1 on a finer
# mesh; the fit starts from E = 5 MPa, K0 = 0.5.  Replace them with your own.

name: example-tunnel           # case name: letters, digits, _ - . (results go to results/<name>)
description: Template - E and K0 from an inclinometer, an extensometer and settlement points  # free text

geometry:                      # half-model of a circular tunnel (symmetric about x = 0)
  radius: 3.0                  # tunnel radius R [m]
  axis_depth: 10.0             # depth of the tunnel axis below the surface [m]; must exceed R
  width: 40.0                  # model width from the symmetry axis to the far side [m]
  depth: 30.0                  # depth of the model's bottom boundary [m]; below the invert

ground:                        # initial state and stiffness of the ground
  unit_weight: 20.0            # unit weight gamma [kN/m3]; vertical stress = -gamma * depth
  K0: 1.0                      # coefficient of earth pressure at rest [-] of every layer
  layers:                      # from the surface downwards; the first layer starts at top: 0
    - name: clay               # layer name (letters, digits, _ -); parameters refer to it: E[clay]
      top: 0.0                 # depth of the layer's top [m]
      E: 10 MPa                # Young's modulus [kPa] or a string with a unit (Pa, kPa, MPa, GPa)
      nu: 0.49                 # Poisson's ratio [-], 0 <= nu < 0.5 (0.49: undrained)
      # K0: 0.8                # optional: this layer's own K0 (overrides ground.K0)
      # model: mohr-coulomb    # optional: a ground that yields (default linear-elastic), then also:
      # c: 20 kPa              #   cohesion c' [kPa]
      # phi: 28                #   friction angle phi' [degrees], 0 < phi < 70
      # psi: 0                 #   dilation angle [degrees], 0 <= psi <= phi
      # tension: 5 kPa         #   optional tension cut-off [kPa], at most c / tan(phi)

mesh:                          # gmsh triangles; meshes are cached (env GEOBACK_CACHE)
  size_tunnel: 0.4             # element size at the tunnel wall [m] (default R/8)
  size_far: 4.0                # element size at the far boundaries [m] (default domain/12)
  # size_instruments: 0.5      # optional: element size along the instruments [m]
  order: 2                     # element order: 2 = quadratic triangles (default), 1 = linear

instruments:                   # readings are displacements [m] in station order unless noted
  - name: I1                   # unique instrument name (letters, digits, _ - .); inclinometer beside the tunnel
    kind: inclinometer         # vertical borehole; slopes integrated from the reference end
    x: 5.0                     # horizontal position of the borehole [m]
    toe_depth: 24.0            # depth of the borehole's toe [m]
    head_depth: 0.0            # depth of the borehole's head [m] (default 0)
    reference: toe             # end the readings are integrated from: toe (assumed fixed) or head
    spacing: 3.0               # distance between stations [m] (or give lengths: [l1, l2, ...])
    stations: 7                # number of stations: depths 21, 18, ..., 3 m from the toe upwards
    sigma: 0.001               # standard deviation of one slope reading [rad]
    var_b: 0.0                 # variance of the integration constant B (toe displacement) [m2]
    reading_type: displacement # readings are integrated displacements [m] (or primary: slopes)
    readings: [-0.0134754, -0.020579, -0.0331059, -0.0504841, -0.048834, -0.0269067, -0.0143154]  # [m], toe to head
    # readings_file: I1.csv    # alternative to readings: a CSV file, relative to this file, matched by
    #                          # station, depth or distance (every column used, mapped or ignored):
    # columns: {depth: "Teufe [m]"}   # the file's header of a column geoback does not know by name
    # ignore_columns: [Datum]  # columns geoback is to leave unread
    # stage: lined             # with several construction stages: the stage of a list or a file without a stage column

  - name: X1                   # extensometer above the crown
    kind: extensometer         # sliding micrometer / extensometer along a straight line
    start: [0.0, 0.0]          # reference end [x, y] [m]: the head at the surface (surveyed)
    end: [0.0, -6.5]           # other end [x, y] [m]; displacement positive from start to end
    spacing: 1.25              # distance between stations [m]
    stations: 5                # number of stations: depths 1.25 ... 6.25 m
    sigma: 0.0005              # standard deviation of one length-change reading [m]
    var_a: 1.0e-6              # variance of the integration constant A (head survey) [m2]
    readings: [0.0339722, 0.0378532, 0.0430446, 0.0509688, 0.0649946]   # [m], from the head down

  - name: S1                   # surface settlement points
    kind: points               # settlement points / prisms: displacement components at points
    points:                    # [x, y] of each point [m]; here on the surface (y = 0)
      - [0.0, 0.0]
      - [2.5, 0.0]
      - [5.0, 0.0]
      - [7.5, 0.0]
      - [10.0, 0.0]
      - [15.0, 0.0]
      - [20.0, 0.0]
    components: [uy]           # measured components per point: ux (horizontal), uy (vertical, up +)
    sigma: 0.001               # standard deviation of each reading [m]
    readings: [-0.0304, -0.0294, -0.0270, -0.0245, -0.0226, -0.0202, -0.0186]   # [m], point by point
    # sign: settlement         # readings positive down (surveyors' settlements): u_y = -reading
    # point_ids: [SP-01, SP-02, SP-03, SP-04, SP-05, SP-06, SP-07]   # IDs of a file's point column

parameters:                    # what to identify: E[layer], nu[layer], K0, K0[layer], ...
  - name: E[clay]              # Young's modulus of layer clay [kPa]
    initial: 5 MPa             # starting value of the fit (same units as the parameter)
    bounds: [100, 1.0e6]       # optional: [lower, upper] [kPa]
    # log: true                # optional: iterate on ln(E) (positive parameters only)
    # prior: {mean: 8000, std: 4000}   # optional Gaussian prior information [kPa]
  - name: K0                   # coefficient of earth pressure at rest [-]
    initial: 0.5               # starting value [-]
    bounds: [0.05, 5.0]        # optional: [lower, upper] [-]

fit:                           # the maximum-likelihood fit (all settings optional)
  method: lm                   # lm (Levenberg-Marquardt), lm-scaled or gn (Gauss-Newton)
  max_iterations: 30           # stop (status "not converged") after this many iterations
  mu0: 10.0                    # initial Levenberg-Marquardt damping [-]
  step_tol: 1.0e-6             # converged when the relative parameter step is below this
  objective_tol: 1.0e-10       # ... or when the relative change of J is below this
  weighting: full              # C_x in J: full (the instruments' covariance), diagonal or identity

forecasts:                     # optional: forecast at the estimate with a 95 % band (forecast.csv, figures)
  - name: trough               # the surface settlement trough
    kind: line                 # line | points | convergence | instrument (its next readings) | lining (N, M, V)
    start: [0.0, 0.0]          # [x, y] [m]
    end: [30.0, 0.0]           # [x, y] [m]
    points: 31                 # evenly spaced points
    component: uy              # ux or uy (up +)
    alert: 0.05                # optional: report the probability that |uy| exceeds 50 mm
    # stage: lined             # with construction stages: the stage forecast (default: the last)

# design:                      # optional, for `geoback design`: where would one more instrument pay off?
#   forecasts: [trough]        # narrow these forecasts (default: all; or objective: parameters)
#   candidates:                # instruments as above, without readings
#     - name: I2
#       kind: inclinometer
#       x: 8.0
#       vary: {x: [4, 8, 12, 16]}   # one candidate per value
#       toe_depth: 24.0
#       spacing: 3.0
#       stations: 7
#       sigma: 0.001

output:                        # what `geoback run` writes (optional)
  # dir: results/example-tunnel   # optional: results folder, relative to this file
  vtu: true                    # write the displacement/stress field as field.vtu (ParaView)
"""


def write_template(path: str | Path, force: bool = False) -> Path:
    """Write the template case to `path`; refuse to overwrite an existing file unless `force`."""
    path = Path(path)
    if path.is_dir():
        raise GeobackError(f"{path} is a folder; give a file name such as {path / 'case.yaml'}")
    if path.exists() and not force:
        raise GeobackError(f"{path} already exists; use --force to overwrite it")
    write_atomic(path, TEMPLATE)
    try:  # an ordinary text file honouring the umask (write_atomic's temp files are 0600)
        mask = os.umask(0)
        os.umask(mask)
        path.chmod(0o666 & ~mask)
    except OSError:  # pragma: no cover - e.g. a file system without permissions
        pass
    return path
