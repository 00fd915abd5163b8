"""Scene files: a whole static simulation described in TOML.

Schema
------
::

    [mesh]                     # required: The tetrahedral mesh: exactly one of file, box or surface.
    file = "beam.vtu"          # mesh file, relative to the scene file: .tet or any volume format meshio reads
    # box = { size = [1, 0.1, 0.1], cells = [8, 2, 2] }   # a box mesh instead of a file
    # surface = "robot.stl"    # closed triangle surface (.stl, .obj, .ply, .off), relative to the scene file,
                               # filled with tetrahedra by sf.tetrahedralize (fTetWild: the optional extra 'mesh')
    # edge_length = 0.004      # target edge length of the tetrahedra filling surface, after scale (default: 1/20
                               # of the bounding-box diagonal), m
    scale = 1                  # multiplies all coordinates (for box: size and origin)
    axes = ["x", "y", "z"]     # after scale, new axis i is old axis axes[i], with its sign: a signed permutation
                               # of x, y, z; ["x", "-z", "y"] turns a y-up mesh into a z-up one

    [material]                 # required: The material: compressible Neo-Hookean, exactly one of youngs_modulus +
                               # poisson_ratio or shear_modulus + lame_lambda; decoupled Mooney-Rivlin, exactly
                               # one of c10 + c01 + d1; decoupled Yeoh, exactly one of c10 + c20 + c30 + d1 + d2 +
                               # d3; decoupled Ogden, exactly one of mu:0 + alpha:0 + mu:1 + alpha:1 + mu:2 +
                               # alpha:2 + d1.
    model = "neo-hookean"      # the material model (sorofem.materials.MODELS)
    youngs_modulus = 66e3      # Young's modulus E (with poisson_ratio), Pa
    poisson_ratio = 0.45       # Poisson's ratio nu (with youngs_modulus)
    # shear_modulus = 22.76e3   # shear modulus mu (with lame_lambda), Pa
    # lame_lambda = 204.8e3    # Lame's first parameter lambda, > 0 for kind = "mixed" (with shear_modulus), Pa
    density = 1080             # density rho (only matters under gravity and in dynamics), kg/m^3 (default 0)

    [[material.region]]        # optional: Other material values for some elements; values not given are the
                               # [material] table's, and a later entry overrides an earlier one where they
                               # overlap.
    name = "tip"               # name of the region, unique; [estimate] params may then name it, e.g.
                               # "shear_modulus:NAME"
    box = { min = [0.3, -1, -1], max = [0.4, 1, 1] }   # select the elements whose centroid is in this box, m
    # cells = [0, 1, 2]        # select these elements (tetrahedron indices, 0-based)
    youngs_modulus = 132e3     # Young's modulus E (with poisson_ratio), Pa

    [formulation]              # optional: Finite element formulation.
    kind = "standard"          # displacement only ("standard") or displacement + nodal pressure ("mixed", no
                               # locking as nu -> 0.5)
    volumetric = "log"         # volumetric measure c(J): ln J ("log") or J - 1 ("linear")
    pressure_mass = "consistent"   # pressure mass matrix of the mixed formulation

    [[fixed]]                  # optional: Supports: exactly one of nodes or box; each entry must select at least
                               # one node.
    # nodes = [0, 1, 2]        # node indices, 0-based
    box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }   # the nodes inside this closed box, m
    displacement = [0, 0, 0]   # prescribed displacement of the selected nodes, m

    [loads]                    # optional: External loads.
    gravity = [0, 0, -9.81]    # acceleration of gravity, m/s^2 (default [0, 0, 0])
    forces = [{ nodes = [5, 6], force = [0, 0, -0.1] }]   # nodal forces, N per node

    [solver]                   # optional: Newton solver options (sorofem.solver.SolveOptions).
    tolerance = 1e-8           # Newton stops when the residual norm over the load norm is below this
    max_iterations = 50        # Newton iterations per load step
    load_steps = 1             # equal load increments (the solver may cut a step back)
    max_cutbacks = 8           # times a failed load step may be halved before the solve gives up

    [[cable]]                  # optional: A cable embedded in the mesh (sorofem.Cable): a chain of unilateral
                               # springs (model = "springs": stiffness, actuation) or a sliding tendon (model =
                               # "tendon": pull or tension); points, or start + direction + length + divisions.
    # points = [[0, 0.01, 0.01], [0.2, 0.01, 0.01], [0.4, 0.01, 0.01]]   # the cable's points at rest, m
    start = [0, 0.01, 0.01]    # first point of a straight cable, m
    direction = [1, 0, 0]      # direction of a straight cable (any non-zero length)
    length = 0.4               # length of a straight cable, m
    divisions = 10             # equal segments of a straight cable
    model = "springs"          # a chain of unilateral springs bonded to the body, or an inextensible tendon
                               # sliding through its points (the last one tied) with one tension
    stiffness = 100e3          # stiffness of each segment spring (springs: required), N/m
    actuation = 0.8            # springs: alpha, segment rest lengths are scaled by it (1 rest, < 1 pulled)
                               # (default 1)
    # pull = 0.01              # tendon: pulled length, the tendon is held at L <= L0 - pull (exactly one of pull
                               # and tension), m
    # tension = 2              # tendon: tension (exactly one of pull and tension), N
    transition = 0.001         # width of the smooth slack-taut transition, fraction of a segment's rest length
    anchor_first = false       # the first point is fixed in the world (a motor)
    snap_tolerance = 0         # points this far outside the mesh attach to the nearest tet, m
    outside = "error"          # points farther outside are an error, or free nodes with their own mass
    free_node_mass = 0         # mass of each free node, kg
    damping = 0                # dashpot of each segment: a force damping * dL/dt in time integration (static
                               # solves are unaffected), N s/m

    [[obstacle]]               # optional: A rigid obstacle the body cannot pass through (contact by Incremental
                               # Potential Contact, optional Coulomb friction): exactly one of plane, sphere, box
                               # or mesh.
    # name = "table"           # name of the obstacle, unique; [target] contact_force may then name it
    plane = { point = [0, 0, -0.06], normal = [0, 0, 1] }   # a half-space (a floor, a wall), m
    # sphere = { center = [0.3, 0.05, -0.1], radius = 0.03 }   # a solid ball, m
    # box = { min = [0.3, 0, -0.2], max = [0.4, 0.1, -0.1] }   # a solid axis-aligned box (sorofem.Box), m
    # mesh = { file = "cup.stl", scale = 0.001 }   # a triangle surface from a file
    friction = 0.5             # Coulomb friction coefficient between this obstacle and the body (default 0)
    # path = [[0, 0, 0, 0], [0.5, 0, 0, 0.02]]   # keyframes of a prescribed translation, linearly interpolated
                                                 # and held outside their range, followed with [dynamics] (static
                                                 # solves use t = 0), s, m

    [contact]                  # optional: Contact settings: the [[obstacle]] entries' and the body's contact with
                               # itself (sorofem.Body.set_contact).
    # dhat = 0.0001            # activation distance of the contact barrier: the body rests a fraction of it away
                               # from an obstacle (default: 1 % of the mean boundary edge length), m
    # self_contact = true      # the body's boundary surface may touch itself (frictionless; its forces are part
                               # of the contact forces and sum to zero) (default false)
    adaptive_stiffness = true   # the barrier stiffness adapts as in IPC (balanced at each time step's start,
                                # within [stiffness, 100 stiffness]); false keeps it at stiffness (trajectory
                                # gradients through contact are exact with both)

    [dynamics]                 # optional: Integrate in time (implicit Euler, lumped mass; density > 0) instead of
                               # a static solve.
    dt = 0.01                  # time step, s; required
    steps = 200                # number of time steps; required
    mass_damping = 0           # Rayleigh alpha_M, 1/s
    stiffness_damping = 0      # Rayleigh beta_K, s
    save_every = 1             # write a frame every this many steps (plus the first and last)
    initial = "rest"           # start at rest from the rest shape, or from the static equilibrium (loads,
                               # actuations)
    actuation = [[[0, 1], [0.5, 0.8]]]   # one array of [time, value] keyframes per [[cable]], linearly
                                         # interpolated and held outside their range: alpha (springs, > 0), pull
                                         # in m or tension in N (tendons, as commanded) (default: each cable keeps
                                         # its command), s, -

    [target]                   # optional: What sorofem estimate / control should meet (sorofem.Target): where
                               # parts of the body should be, or the force an obstacle exerts on it; exactly one
                               # of nodes, points, surface or contact_force; nodes and points with one of
                               # positions or positions_file (a goal), or tracks or tracks_file (a recorded
                               # motion, with [dynamics]).
    nodes = [17, 18, 19]       # observed mesh nodes (with positions)
    # points = [[0.1, 0.01, 0.01]]   # observed marker points at rest, inside the mesh (with positions), m
    positions = [[0.1, 0, -0.01], [0.1, 0.02, -0.01], [0.1, 0.02, 0.01]]   # goal position of each node or point,
                                                                           # m
    # positions_file = "markers.csv"   # the goal positions from a file instead, relative to the scene file: .npy
                                       # (k, 3) or a .csv / .txt table with columns x, y, z
                                       # (sorofem.io.read_points)
    # tracks = [[0.02, 0, 0.4, 0.05, 0.0986]]   # a recorded motion instead (with [dynamics]): where marker number
                                                # `marker` (0-based, an entry of nodes or points) was at `time`, a
                                                # frame k dt of [dynamics]; a marker may miss frames, s, -, m
    # tracks_file = "tracks.csv"   # the recorded motion from a file instead, relative to the scene file: a .csv /
                                   # .txt table, a header line time, marker, x, y, z (any order), then a row per
                                   # marker seen in a frame
    # surface = "goal.obj"     # goal surface file, relative to the scene file
    # scale = 1                # coordinate scale of the surface files
    # rest = "rest.obj"        # the body's own rest surface (default: the mesh boundary)
    # contact_force = { obstacle = "table", force = 0.05 }   # the total force an [[obstacle]] should exert on the
                                                             # body, instead of positions, N

    [estimate]                 # optional: sorofem estimate (sorofem.estimate): fit these parameters so that the
                               # equilibrium meets [target]; with [dynamics], so that the motion of [dynamics]
                               # meets the recorded [target] tracks.
    params = ["shear_modulus", "lame_lambda"]   # names of the parameters to fit (sorofem.inverse.PARAMETERS); a
                                                # material one may name a region, "shear_modulus:tip"; with
                                                # [dynamics] also the Rayleigh coefficients mass_damping (1/s) and
                                                # stiffness_damping (s) and the dashpot cable_damping (N s/m) of
                                                # the one spring cable, scalars only; required
    x0 = [20e3, 200e3]         # initial values, one per parameter (an array for a field; > 0 for a damping
                               # coefficient); required
    bounds = [[1000, 1e6], [1000, 100e6]]   # one [lo, hi] per parameter
    method = "least-squares"   # optimiser
    starts = 0                 # number of extra random starts (not with [dynamics])

    [control]                  # optional: sorofem control (sorofem.control): find cable commands (alphas, tendon
                               # pulls or tensions) that bring [target] closest; with [dynamics], a schedule of
                               # them (keyframes) that brings [target] there at reach_time and holds it to the end
                               # of the run.
    cables = [0]               # indices of the [[cable]] entries to actuate (default: all)
    bounds = [[0.3, 1]]        # one range [lo, hi] per cable in its command's units: alpha (springs, > 0; default
                               # [0.3, 1]), pull in m (default [0, L0/4]) or tension in N (required)
    method = "l-bfgs-b"        # optimiser (with [dynamics]: l-bfgs-b only)
    keyframe_times = [0.1, 0.2, 0.3, 0.4, 0.5]   # with [dynamics] (required there): the times of the schedule's
                                                 # keyframes, increasing, within dt * steps; each cable's command
                                                 # is piecewise linear through them from its [[cable]] command at
                                                 # t = 0, and held after the last, s
    reach_time = 0.5           # with [dynamics] (required there): the time T, a multiple of dt, from which
                               # [target] should be reached and held to the end of the run, s

    [output]                   # optional: What sorofem run writes and where (every file but deformed.vtu is on by
                               # default); estimate and control also follow directory, summary, vtu and png.
    directory = "results/beam"   # output folder, relative to the scene file (created); `--out DIR` on the command
                                 # line overrides it
    summary = true             # write summary.json (solver report, timings, material, extreme values)
    vtu = true                 # write result.vtu (the rest mesh with point data displacement, pressure and cell
                               # data J, von Mises: Warp By Vector in ParaView shows the deformed body)
    deformed = false           # also write deformed.vtu: the same data on the deformed mesh (to open without a
                               # filter; do not warp it again)
    png = true                 # write the figures: shape.png and convergence.png, trajectory.png with [dynamics],
                               # fit.png (and profile.png) for estimate and control
    cables = true              # write cables.vtu (the cables as lines with their tension; static scenes with
                               # [[cable]] entries)
    pvd = true                 # write trajectory.pvd and its frames in trajectory/ (scenes with [dynamics])
    color_by = "displacement"   # field that colours the deformed surface in shape.png: displacement magnitude,
                                # von Mises stress, pressure (kind = "mixed" only) or the volume ratio J

Validation is strict: an unknown key, a wrong type, a missing mesh file, a ``[[fixed]]``
entry selecting no node, a ``[[material.region]]`` entry selecting no element or an
out-of-range value raises :class:`~sorofem.SceneError` with the file, the dotted key (e.g.
``fixed[0].box.min``) and, when it can be found, the line.

Every key, its type, range, default and meaning is written once, as data
(:data:`sorofem.scene._keys.SCENE`, which reads material parameters, solver options and cable
options from where they are declared): the validator reads it, and so does :func:`json_schema`,
which turns it into a JSON Schema (draft 2020-12) of the file (``sorofem schema``; the repository
keeps a copy in ``docs/scene.schema.json``). The annotated example above and README.md's key
table are generated from it too (:mod:`sorofem.scene.generate`, ``make generate``). Editors that understand TOML schemas (VS Code's Even Better
TOML, taplo) complete and check scene files against it when the file starts with a
``#:schema ./scene.schema.json`` line (a path relative to the scene file, or a URL). What the
schema cannot say (node and element indices within the mesh, files that exist, one value per
cable or parameter) only the validator checks.

Examples
--------
>>> import sorofem as sf
>>> scene = sf.Scene.load("cantilever.toml")      # doctest: +SKIP
>>> result = scene.solve()                        # doctest: +SKIP
>>> schema = sf.scene.json_schema()               # a dict, ready for json.dump
>>> sorted(schema["properties"])[:3]
['cable', 'control', 'dynamics']
"""

from __future__ import annotations

from ._keys import SCENE, TOP_KEYS, json_schema, schema_text
from ._scene import PER_SOLVE_CABLE_KEYS, Scene, structure_key
from ._spec import Checker, Field, Number, Table, Tables

__all__ = ["Scene", "json_schema", "schema_text", "TOP_KEYS", "SCENE", "Checker", "Field", "Number", "Table",
           "Tables", "structure_key", "PER_SOLVE_CABLE_KEYS"]

# Documented (and pickled) as members of this package, whichever private module holds them.
for _public in (Scene, json_schema, schema_text):
    _public.__module__ = __name__
