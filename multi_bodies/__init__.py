"""The many-body problem: the scripts at their published paths, the library in subpackages.

Top level (what a user runs, from inside ``multi_bodies/``)::

    multi_bodies.py             dynamics (deterministic and Brownian), rollers
    multi_bodies_utilities.py   static problems: body mobility, mobility, resistance
    advise.py                   the advisor
    clones_to_vtk.py, render.py pictures and VTK files of a run
    ensemble.py                 replicas and parameter sweeps
    multi_bodies_functions.py   the published override module (for user files only)

The library, one job a subpackage::

    files/      input files and structure files: the option table and parser,
                .vertex/.clones/.slip readers, snapshots (.clones/.config), generators
    solver/     the mobility problem: default physics (pair laws), user hooks,
                the frozen Model, the problems (one protocol) and their one solve
    run/        a run: set-up shared by every script, run output and restart
                records, the dynamic run, VTK and velocity-field output
    ensembles/  replicas on Dask and their statistics
    advice/     the advisor's measurements, models and report

Floors (a module imports only from its own floor or below; ``tests/test_layout.py``
checks this from the import graph)::

    1  utils, body.geometry (quaternions, minimum image), mobility
    2  body, stochastic_forcing
    3  multi_bodies.files
    4  multi_bodies.solver
    5  quaternion_integrator (the schemes), sphere
    6  multi_bodies.run, many_bodyMCMC, boomerang
    7  multi_bodies.advice, multi_bodies.ensembles
    8  multi_bodies.multi_bodies_functions (the published override module)
    9  the scripts
"""
