"""Reader of the input file of the scripts: typed options with defaults.

Format: one option per line, ``name value``; everything
after a ``#`` is a comment; blank lines are skipped; a repeated option
replaces the earlier one, except ``structure``, of which every line is kept
(one per body type, in order).

Unlike the published code, every value is checked when it is read: an
unknown option, a value of the wrong type, a value outside the option's
rule in ``OPTION_TABLE`` or a malformed ``structure`` line raises
``utils.UserInputError`` naming the file, the line and what was expected.
Each option is declared once, in ``OPTION_TABLE`` (kind, default, rule,
the programs that use it); ``check_options(options, program)`` applies the
rules of one program (the scripts call it through ``run_setup.prepare``),
and the "ignored by" warnings read the table's ``used_by`` column.  Options that only later versions of the published code know are
refused as unsupported rather than silently ignored (SPEC decision 9).
"""
import difflib
import math
import os
from collections import namedtuple

from multi_bodies.files.scheme_table import moves_rollers, scheme_entry, scheme_names
from utils import UserInputError, read_text_file, warn_user


# ---------------------------------------------------------------------------------------------- the table
# Every option is declared once, in OPTION_TABLE below: its kind, default, allowed values (a rule, with the
# fix a message gives), and the programs that use it.  The parser converts and checks from it
# (``check_options``), the "option X is ignored by ..." warnings read its ``used_by`` column
# (``unused_option_warnings``), and the docs test compares doc/options.md with it.
#
# Usage tags of ``used_by``: 'static' (multi_bodies_utilities.py), 'dynamic' (multi_bodies.py, every scheme),
# 'stochastic' (the dynamic stochastic schemes only), 'rollers' (the dynamic roller schemes only), 'mcmc'
# (many_bodyMCMC/many_body_MCMC.py), 'lubrication' (the lubrication schemes only).  An empty ``used_by``: read for
# compatibility, no effect.
PROGRAMS = ('dynamic', 'static', 'mcmc')
# The schemes' names, kinds and needs are the scheme registry's (multi_bodies.files.scheme_table); these are its
# lists (quaternion_integrator.schemes holds the classes and refuses one the registry does not know).
STATIC_SCHEMES = scheme_names(kind='static')
DETERMINISTIC_SCHEMES = scheme_names(kind='deterministic', articulated=False)
STOCHASTIC_SCHEMES = scheme_names(kind='stochastic')
ARTICULATED_SCHEMES = scheme_names(articulated=True)
DYNAMIC_SCHEMES = DETERMINISTIC_SCHEMES + STOCHASTIC_SCHEMES + ARTICULATED_SCHEMES
MCMC_MOVES = ('all_bodies', 'one_body')                        # many_bodyMCMC.sampler.MOVES
MCMC_ENERGY_IMPLEMENTATIONS = ('auto', 'python', 'C++', 'pycuda')  # many_bodyMCMC.mcmc_energy.IMPLEMENTATIONS
# Largest magnitude of a number option: its square still fits in a double.
LARGEST_VALUE = 1e150
# eta and blob_radius beyond these bounds make eta a^3 (rotational resistance) over- or underflow.
SCALE_RANGE = (1e-50, 1e50)


def mobility_implementation_names():
    """Names of the mobility registry (``mobility.interface.implementation_names``) and ``auto``, ``auto_no_wall``."""
    from mobility.interface import implementation_names
    return tuple(implementation_names()) + ('auto', 'auto_no_wall')


def vector_product_names():
    """The names of ``mobility_implementation_names`` and ``spectral`` (the periodic and confined boxes of
    doc/periodic.md: a matrix-free product without dense blocks, so not a ``mobility_blobs_implementation``)."""
    return mobility_implementation_names() + ('spectral',)


class Range:
    """Allowed numbers: ``low`` <(=) value <(=) ``high`` (None: no bound).

    ``text`` says it in a message ("positive", ">= 0", ...); ``fix`` (optional)
    says why or what to do.
    """

    def __init__(self, low=None, high=None, low_open=False, high_open=False, text=None, fix=''):
        self.low, self.high, self.low_open, self.high_open, self.fix = low, high, low_open, high_open, fix
        if text is None:
            if high is None and low == 0:
                text = 'positive' if low_open else '>= 0'
            elif high is None:
                text = ('> %g' if low_open else 'at least %g') % low
            else:
                text = 'between %g and %g' % (low, high)
        self.text = text

    def allows(self, value):
        if self.low is not None and not (value > self.low if self.low_open else value >= self.low):
            return False
        if self.high is not None and not (value < self.high if self.high_open else value <= self.high):
            return False
        return True

    def message(self, where, name, value, known=False):
        shown = ('%d' % value) if isinstance(value, int) else ('%g' % value)
        return '%s: %s must be %s%s, got %s' % (where, name, self.text, ' (%s)' % self.fix if self.fix else '',
                                                 shown)


class Choice:
    """Allowed words: ``names`` (a tuple, or a callable returning one: read when checked)."""

    def __init__(self, names, fix=''):
        self._names, self.fix = names, fix

    @property
    def names(self):
        return tuple(self._names() if callable(self._names) else self._names)

    @property
    def text(self):
        names = self.names
        return ' or '.join(names) if len(names) <= 2 else 'one of ' + ', '.join(names)

    def allows(self, value):
        return value in self.names

    def message(self, where, name, value, known=False):
        if known:  # a valid name, but not for this program
            return "%s: %s '%s' is not for this program; %s must be %s%s" % (
                where, name, value, name, self.text, ' (%s)' % self.fix if self.fix else '')
        close = difflib.get_close_matches(str(value), list(self.names), n=1)
        hint = "; did you mean '%s'?" % close[0] if close else ''
        return "%s: unknown %s '%s'%s; %s must be %s%s" % (where, name, value, hint, name, self.text,
                                                            ' (%s)' % self.fix if self.fix else '')


class Option(namedtuple('Option', ['kind', 'default', 'rule', 'used_by', 'program_rules', 'dynamics'],
                        defaults=(True,))):
    """One row of OPTION_TABLE.

    kind : str, int, float, floats2, floats3, floats9 (one to nine), ints2, grid9, bool, optional_str, optional_int
    default : the value when the file does not set the option
    rule : Range, Choice or None, checked whatever the program
    used_by : tuple of usage tags (see above); () = no effect
    program_rules : {program: rule}, a stricter rule for one program (e.g. dt > 0 for a dynamic run)
    dynamics : True (the default) when the value can change a trajectory, or where a restart reads it from: a
        restart must keep it (the restart fingerprint holds it, ``restart_records.run_fingerprint``); False when
        it cannot change the numbers (n_steps, n_save, outputs, seed once a record holds the generator): a
        restart may change it and still continues exactly
    """


def _option(kind, default, used_by, rule=None, dynamics=True, **program_rules):
    return Option(kind, default, rule, tuple(used_by), program_rules, dynamics)


SDM = ('static', 'dynamic', 'mcmc')
SD = ('static', 'dynamic')
DM = ('dynamic', 'mcmc')
_SCALE = Range(SCALE_RANGE[0], SCALE_RANGE[1], text='positive, between %g and %g' % SCALE_RANGE,
               fix='beyond that eta a^3 over- or underflows in double precision; rescale the units')
_SAVE_CLONES = Choice(('one_file_per_step', 'one_file'))
# 'numba' (a name of later published versions) is an alias of the compiled all-pairs kernel 'C++', and so is
# 'radii_numba' (the published name of the forces with per-blob radii, which C++ and python use when given);
# 'tree_numba' (ditto) is the compiled cell list (pairs beyond 2 blob_radius + 30 debye_length neglected).
_FORCE_IMPLEMENTATIONS = ('None', 'python', 'C++', 'numba', 'radii_numba', 'tree_numba', 'pycuda', 'auto')

OPTION_TABLE = {
    'scheme': _option('str', 'deterministic_forward_euler', SD, Choice(STATIC_SCHEMES + DYNAMIC_SCHEMES),
                      static=Choice(STATIC_SCHEMES,
                                    fix='it is not a static problem: the dynamic schemes run with multi_bodies.py'),
                      dynamic=Choice(DYNAMIC_SCHEMES,
                                     fix='it is a static problem: run it with multi_bodies_utilities.py')),
    'n_steps': _option('int', 0, DM, Range(0, fix='the index of the last step'), dynamics=False),
    'initial_step': _option('int', 0, DM, Range(0, fix='0 starts a new run, k > 0 restarts from saved step k'),
                            dynamics=False),
    'n_save': _option('int', 1, DM, Range(1, fix='save every n_save steps'), dynamics=False),
    'restart_inexact': _option('bool', False, DM, dynamics=False),
    'n_relaxation': _option('int', 0, (), dynamics=False),
    'dt': _option('float', 0.0, ('dynamic',), Range(0, fix='the time step'),
                  dynamic=Range(0, low_open=True, fix='the time step of a dynamic run')),
    'eta': _option('float', 1.0, SD, _SCALE),
    'g': _option('float', 1.0, SDM),
    'blob_radius': _option('float', 1.0, SDM, _SCALE),
    'tracer_radius': _option('float', 0.0, ('static',), Range(0, fix='0 gives the point velocity'), dynamics=False),
    'kT': _option('float', 1.0, ('stochastic', 'mcmc'), Range(0, fix='the thermal energy'),
                  mcmc=Range(0, low_open=True, fix='the sampler weighs by exp(-U/kT)')),
    'output_name': _option('str', 'run', SDM, dynamics=False),
    'random_state': _option('optional_str', None, DM, dynamics=False),
    'seed': _option('optional_int', None, DM, Range(0, text='a non-negative integer'), dynamics=False),
    'random_generator': _option('str', 'auto', DM, Choice(('auto', 'default', 'published')), dynamics=False),
    'repulsion_strength_wall': _option('float', 1.0, SDM),
    'debye_length_wall': _option('float', 1.0, SDM, Range(0, low_open=True, fix='the repulsion laws divide by it')),
    'repulsion_strength': _option('float', 1.0, SDM),
    'debye_length': _option('float', 1.0, SDM, Range(0, low_open=True, fix='the repulsion laws divide by it')),
    'mobility_blobs_implementation': _option('str', 'python', SD, Choice(mobility_implementation_names)),
    'mobility_vector_prod_implementation': _option('str', 'python', SD, Choice(vector_product_names)),
    'blob_blob_force_implementation': _option('str', 'None', SD, Choice(_FORCE_IMPLEMENTATIONS)),
    'body_body_force_torque_implementation': _option('str', 'None', SDM, Choice(('None', 'python'))),
    'solver_tolerance': _option('float', 1e-8, SD, Range(0, 1, True, True, fix='a relative tolerance, e.g. 1e-8')),
    # articulated schemes only (max-norm of the joint residuals, length units)
    'nonlinear_solver_tolerance': _option('float', 1e-8, ('dynamic',),
                                          Range(2.2205e-16, text='at least 2.2205e-16 (the machine epsilon)',
                                                fix='the largest joint residual, e.g. 1e-8; the correction\'s '
                                                    'least-squares solve cannot stop below the round-off')),
    'rf_delta': _option('float', 1e-3, ('stochastic',), Range(0, low_open=True, fix='1e-3 is the default')),
    'save_clones': _option('str', 'one_file_per_step', DM, _SAVE_CLONES),
    'periodic_length': _option('floats3', (0.0, 0.0, 0.0), SDM),
    'omega_one_roller': _option('floats3', (0.0, 0.0, 0.0), ('rollers',)),
    'free_kinematics': _option('bool', True, ('rollers',)),
    'domain': _option('str', 'single_wall', ('rollers',), Choice(('single_wall', 'no_wall', 'in_plane'))),
    # mobility_vector_prod_implementation spectral only (doc/periodic.md; checked by multi_bodies.solver.periodic)
    'spectral_geometry': _option('str', 'auto', SD, Choice(('auto', 'triply_periodic', 'doubly_periodic_open',
                                                            'doubly_periodic_wall', 'doubly_periodic_slit'))),
    'spectral_z_bounds': _option('floats2', None, SD),
    'spectral_kernel': _option('str', 'w6', SD, Choice(('w6', 'w5', 'w4', 'w6w5', 'w6w4', 'w5w4'))),
    'spectral_noise': _option('str', 'lanczos', ('stochastic',), Choice(('lanczos', 'fluctuating'))),
    # how a spectral input is read (doc/periodic.md): auto is the published Spectral_Multiblob_Roller form when no
    # other spectral_* line is given over a wall, the manual's reading otherwise
    'spectral_reading': _option('str', 'auto', SD, Choice(('auto', 'published', 'package'))),
    # gravity tilt (radians) of the published reader: passed to the hooks as the keyword tilt_angle
    'tilt_angle': _option('float', 0.0, SDM),
    # radius of a multiblob roller that the published Multi_Blob_Two_Rollers program hard-codes (1.0): a hook keyword
    'particle_radius': _option('float', 1.0, SDM, Range(0, low_open=True, fix='the radius of one particle')),
    # lubrication schemes only (doc/lubrication.md): pair cutoff and gap clamp in units of blob_radius, firm repulsion
    'Lub_Cut': _option('float', 4.5, ('lubrication',), Range(2, low_open=True, fix='a centre distance in radii, '
                                                                                  'e.g. 4.5')),
    'firm_delta': _option('float', 1e-4, ('lubrication',), Range(0, 1, True, True, fix='a gap in radii, e.g. 1e-4')),
    'repulsion_strength_firm': _option('float', 0.0, ('lubrication',)),
    'lubrication_handover': _option('str', 'published', ('lubrication',), Choice(('published', 'smooth'))),
    # the GMRES preconditioner (doc/preconditioners.md): iterates differ only within solver_tolerance
    'preconditioner': _option('str', 'auto', SD, Choice(('auto', 'neighbours', 'block_diagonal'))),
    # the factor L of Lanczos' L^{-1} M L^{-T} (doc/preconditioners.md): another sample of the same noise, off by default
    'lanczos_preconditioner': _option('str', 'block_diagonal', ('stochastic',),
                                      Choice(('block_diagonal', 'incomplete_cholesky'))),
    'update_PC': _option('int', 1, ('stochastic',), Range(1, fix='rebuild the preconditioner every update_PC steps')),
    # a speed option, off (None: solver_tolerance) by default: the tolerance of the noise and RFD sub-solves
    'noise_solver_tolerance': _option('float', None, ('stochastic',),
                                      Range(0, 1, True, True, fix='leave it out to use solver_tolerance')),
    'plot_velocity_field': _option('grid9', None, ('static',), dynamics=False),
    'force_file': _option('optional_str', None, ('static',), dynamics=False),
    'velocity_file': _option('optional_str', None, ('static',), dynamics=False),
    'save_body_mobility': _option('bool', False, ('dynamic',), dynamics=False),
    'save_blobs_mobility': _option('bool', False, ('dynamic',), dynamics=False),
    'save_velocities': _option('bool', False, (), dynamics=False),
    'save_vtk': _option('bool', False, ('dynamic',), dynamics=False),
    # the published HydroGrid options, computed by the package (multi_bodies/analysis/hydrogrid.py, doc/analysis.md)
    'call_HydroGrid': _option('bool', False, ('dynamic',), dynamics=False),
    'sample_HydroGrid': _option('int', 1, ('dynamic',), Range(1, fix='sample every sample_HydroGrid steps'),
                                dynamics=False),
    'save_HydroGrid': _option('int', 0, ('dynamic',), Range(0, fix='0 averages over the whole run'),
                              dynamics=False),
    'cells': _option('ints2', (1, 1), ('dynamic',), dynamics=False),  # two ints >= 1, checked by analysis.hydrogrid
    'green_particles': _option('ints2', (0, 0), ('dynamic',), dynamics=False),  # 0 <= i0 <= i1, checked by analysis.hydrogrid
    'slip_file': _option('optional_str', None, (), dynamics=False),
    # phoretic bodies (.Laplace third files, doc/phoretic.md): background c_bg = b0 + G.x + x^T H x, D
    'background_Laplace': _option('floats9', (), SD),
    'diffusion_coefficient': _option('float', 1.0, SD, Range(0, low_open=True, fix='the solute diffusivity')),
    'save_concentration': _option('bool', False, ('dynamic',), dynamics=False),
    'structure_names': _option('optional_str', None, (), dynamics=False),
    # Monte Carlo sampler only (many_bodyMCMC, doc/mcmc.md); 0 step sizes select the published defaults
    'mcmc_move': _option('str', 'all_bodies', ('mcmc',), Choice(MCMC_MOVES)),
    'mcmc_energy_implementation': _option('str', 'auto', ('mcmc',), Choice(MCMC_ENERGY_IMPLEMENTATIONS)),
    'max_translation': _option('float', 0.0, ('mcmc',), Range(0, fix='0 selects the default')),
    'max_angle_shift': _option('float', 0.0, ('mcmc',), Range(0, fix='0 selects the default')),
    'n_burn_in': _option('int', 0, ('mcmc',), Range(0)),
    'target_acceptance': _option('float', 0.3, ('mcmc',), Range(0, 1, True, True)),
}

# Options of later versions of the published code that this package does not implement, with the feature
# they belong to (named in the refusal, so a user knows what is missing rather than only that a line is wrong).
UNSUPPORTED_FEATURES = {
    "HydroGrid's snapshots of the concentration cells": ('save_HydroGrid_cells',),
    'lubrication corrections (the Lubrication solver)': ('stiffness_wall', 'mu', 'vacf'),
    # the cRigid_cFibers codes (Rigid_Object_Main.py, the fibre drivers) over libMobility and DoublyPeriodicStokes
    'the domains of the published cRigid_cFibers codes': ('domType', 'zmin', 'zmax'),
    'a solver of a later published version': ('hydro_interactions', 'slip_length', 'plot_velocity_field_shell',
                                              'hydrodynamic_radius'),
}
UNSUPPORTED_LATER_OPTIONS = tuple(name for names in UNSUPPORTED_FEATURES.values() for name in names)
# Where each missing feature is covered, or why it is not (the second half of every refusal of a later feature).
FEATURE_STATUS = {
    "HydroGrid's snapshots of the concentration cells": 'the package computes S(k) and F(k, t) with the HydroGrid '
                                                        'options, not the cell snapshots; see doc/analysis.md',
    'lubrication corrections (the Lubrication solver)': 'the lubrication schemes read Lub_Cut, firm_delta and '
                                                        'repulsion_strength_firm, not the options of the later '
                                                        'confined solvers; see doc/lubrication.md',
    'a solver of a later published version': 'not available: see doc/examples.md for the published folders',
    'the domains of the published cRigid_cFibers codes': 'domType names the geometry of their compiled mobility '
                                                         '(RPB: one wall; DPBW, DPSC, DP, TP: doubly periodic above '
                                                         'a wall, slit channel, periodic) and zmin, zmax its height; '
                                                         'those inputs are for its own driver Rigid_Object_Main.py, '
                                                         'and this package has neither that driver nor fibres; the '
                                                         'doubly periodic product of the spectral solvers is being '
                                                         'added, see doc/examples.md',
}


def unsupported_feature(name):
    """The feature of a later published version that option ``name`` belongs to."""
    return next(feature for feature, names in UNSUPPORTED_FEATURES.items() if name in names)


def later_feature_refusal(where, what, feature, status=None):
    """The one form of every refusal of a later-version feature: ``where: what is F, a feature of a later published
    version that this package does not have (status); remove it``.  ``status``: where it is covered or why not
    (default ``FEATURE_STATUS[feature]``)."""
    return ('%s: %s belongs to %s, a feature of a later version of the published code that this package does not '
            'have (%s); remove it' % (where, what, feature, FEATURE_STATUS.get(feature, '') if status is None
                                      else status))

ArticulatedSpec = namedtuple('ArticulatedSpec', ['list_vertex_file', 'clones_file', 'const_file', 'ID', 'where'])
ArticulatedSpec.__doc__ = """One ``articulated`` line (doc/articulated.md): the ``.list_vertex``, ``.clones`` and
``.const`` file names, the ID (clones file name without ``.clones``) and ``where``."""

StructureSpec = namedtuple('StructureSpec', ['vertex_file', 'clones_file', 'slip_file', 'ID', 'where',
                                             'velocity_file', 'obstacle', 'laplace_file', 'slip_length_file'],
                           defaults=(None, False, None, None))
StructureSpec.__doc__ = """One ``structure`` or ``obstacle`` line: file names (relative to the working
directory), the structure ID (clones file name without directory and ``.clones``), ``where``
("file, line n") for error messages, ``velocity_file`` (the fourth file of a ``structure`` line: the
prescribed lab-frame velocities ``vx vy vz wx wy wz`` of its bodies, one line per body; None for free
bodies) and ``obstacle`` (True for an ``obstacle`` line: bodies held at zero velocity); ``laplace_file`` and
``slip_length_file``: a ``.Laplace`` or ``.slip_length`` file among the third and later words (any position,
recognised by the suffix as published; doc/phoretic.md), or None."""


def parse_structure_line(name, value, where):
    """The StructureSpec of one ``structure`` (2 to 4 files) or ``obstacle`` (2 or 3 files) line."""
    files = value.split()
    surface = {}
    for suffix in ('.Laplace', '.slip_length'):  # phoretic and slip-length data: any position after two files
        found = [f for f in files[2:] if f.endswith(suffix)]
        if len(found) > 1:
            raise UserInputError("%s: more than one %s file on one line: %s" % (where, suffix, ' '.join(found)))
        surface[suffix] = found[0] if found else None
        files = files[:2] + [f for f in files[2:] if f not in found]
    if name == 'obstacle':
        if len(files) not in (2, 3):
            raise UserInputError("%s: 'obstacle' expects two or three file names (vertex clones [slip]), got "
                                 "%d: '%s'" % (where, len(files), value))
    elif len(files) not in (2, 3, 4):
        raise UserInputError(
            "%s: 'structure' expects two or three file names (vertex clones [slip]), or four for bodies of "
            "prescribed velocity (vertex clones slip velocity; slip None for no slip), got %d: '%s'"
            % (where, len(files), value))
    slip = files[2] if len(files) >= 3 and files[2] != 'None' else None
    velocity = files[3] if len(files) == 4 else None
    return StructureSpec(files[0], files[1], slip, structure_id_from_clones(files[1]), where, velocity,
                         name == 'obstacle', surface['.Laplace'], surface['.slip_length'])


class Options:
    """Typed options of one input file.

    Every name of ``OPTION_TABLE`` is an attribute (defaults filled in);
    ``structures`` is the list of ``StructureSpec`` of the ``structure`` lines in input order,
    ``obstacles`` that of the ``obstacle`` lines (their bodies come after all the structures');
    ``input_file`` the path read; ``where(name)`` says on which line an
    option was set ("<file>, line <n>", or "<file> (default)");
    ``warnings`` the messages about accepted but doubtful lines (printed by
    ``read_input_file``).
    """

    def __init__(self, input_file, values, lines, structures, obstacles=()):
        self.input_file = input_file
        self._lines = dict(lines)
        self.structures = list(structures)
        self.obstacles = list(obstacles)
        self.articulated = []  # ArticulatedSpec per 'articulated' line (set by the parser)
        self.warnings = []
        for name, option in OPTION_TABLE.items():
            setattr(self, name, values.get(name, option.default))

    def where(self, name):
        """Location of option ``name`` for messages."""
        if name in self._lines:
            return '%s, line %d' % (self.input_file, self._lines[name])
        return '%s (option %s not given, default used)' % (self.input_file, name)

    def is_set(self, name):
        """True when the input file gave option ``name``."""
        return name in self._lines

    def as_dict(self):
        """Option values by name (structures excluded)."""
        return {name: getattr(self, name) for name in OPTION_TABLE}

    def replace(self, **values):
        """A copy of these options with ``values`` (name -> typed value) set, each checked against the table
        (the parsed options themselves are never changed after reading)."""
        import copy
        unknown = [name for name in values if name not in OPTION_TABLE]
        if unknown:
            raise KeyError('not an option of the table: %s' % ', '.join(unknown))
        for name, value in values.items():
            if value is not None:
                check_value(name, value, self.where(name))
        twin = copy.copy(self)
        for name, value in values.items():
            setattr(twin, name, value)
        return twin


def options_with(**values):
    """Options of the table's defaults with ``values`` (name -> typed value) set, for schemes and models made
    directly (tests, charts, benchmarks); each value is checked against the table's rule."""
    unknown = [name for name in values if name not in OPTION_TABLE]
    if unknown:
        raise KeyError('not an option of the table: %s' % ', '.join(unknown))
    options = Options('<options_with>', values, {}, [])
    for name, value in values.items():
        if value is not None:
            check_value(name, value, '<options_with>: %s' % name)
    return options


def _convert(kind, name, value, where):
    """Convert the text ``value`` of option ``name`` to its type or raise UserInputError."""
    words = value.split()

    def fail(expected):
        raise UserInputError("%s: option '%s' expects %s, got '%s'" % (where, name, expected, value))

    def finite(word, expected):
        number = float(word)
        if not math.isfinite(number):
            fail(expected + ' (finite: not nan or inf)')
        if abs(number) > LARGEST_VALUE:
            fail(expected + ' of magnitude at most %g (larger values overflow when squared; rescale the units)'
                 % LARGEST_VALUE)
        return number

    if kind in ('str', 'optional_str'):
        if len(words) != 1:
            fail('one word (no spaces)')
        return words[0]
    if kind in ('int', 'optional_int'):
        if len(words) != 1:
            fail('one integer')
        try:
            return int(words[0])
        except ValueError:
            fail('an integer')
    if kind == 'float':
        if len(words) != 1:
            fail('one number')
        try:
            return finite(words[0], 'a number')
        except UserInputError:
            raise
        except ValueError:
            fail('a number')
    if kind == 'bool':
        if len(words) != 1 or words[0] not in ('True', 'False'):
            fail('True or False')
        return words[0] == 'True'
    if kind == 'floats2':
        try:
            numbers = tuple(finite(w, 'two numbers') for w in words)
        except UserInputError:
            raise
        except ValueError:
            fail('two numbers')
        if len(numbers) != 2:
            fail('two numbers')
        return numbers
    if kind in ('floats3', 'floats9'):  # floats9: one to nine numbers (background_Laplace), zero-padded where used
        what, fewest, most = ('three numbers', 3, 3) if kind == 'floats3' else ('one to nine numbers', 1, 9)
        try:
            numbers = tuple(finite(w, what) for w in words)
        except UserInputError:
            raise
        except ValueError:
            fail(what)
        if not fewest <= len(numbers) <= most:
            fail(what)
        return numbers
    if kind == 'ints2':
        try:
            numbers = tuple(int(w) for w in words)
        except ValueError:
            fail('two integers')
        if len(numbers) != 2:
            fail('two integers')
        return numbers
    if kind == 'grid9':
        expected = ('nine values x0 x1 Nx y0 y1 Ny z0 z1 Nz (Nx, Ny, Nz positive integers, x0 < x1, ...; '
                    'x0 = x1 with Nx = 1 gives one point on that axis, e.g. a plane z = z0)')
        if len(words) != 9:
            fail(expected)
        try:
            grid = []
            for axis in range(3):
                low, high = finite(words[3 * axis], expected), finite(words[3 * axis + 1], expected)
                cells = int(words[3 * axis + 2])
                # a degenerate axis (low = high) holds one point: a plane or a line of the published grids
                if cells < 1 or not (high > low or (high == low and cells == 1)):
                    fail(expected)
                grid.append((low, high, cells))
        except UserInputError:
            raise
        except ValueError:
            fail(expected)
        return tuple(grid)
    raise AssertionError('unknown option kind %r' % kind)


def structure_id_from_clones(clones_path):
    """Structure ID: the clones file name without directory and ``.clones`` suffix."""
    base = os.path.basename(clones_path)
    return base[:-len('.clones')] if base.endswith('.clones') else os.path.splitext(base)[0]


def parse_input_text(text, input_file='<input>', program=None):
    """Parse the text of an input file into ``Options`` (see module docstring).

    ``program`` ('dynamic', 'static', 'mcmc' or None) selects the rules and
    warnings of the program that reads the file; None checks every option by
    its general rule and warns as the scheme suggests (static schemes: the
    static script, others: the dynamic one).
    """
    values, lines, structures, repeated = {}, {}, [], []
    obstacles = []
    articulated = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split('#', 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 1)
        name = parts[0]
        where = '%s, line %d' % (input_file, number)
        if len(parts) < 2:
            raise UserInputError("%s: option '%s' has no value; write '%s <value>'" % (where, name, name))
        value = parts[1].strip()
        if name in ('structure', 'obstacle'):
            (structures if name == 'structure' else obstacles).append(parse_structure_line(name, value, where))
            continue
        if name == 'articulated':
            files = value.split()
            if len(files) != 3:
                raise UserInputError("%s: 'articulated' expects three file names (list_vertex clones const), got "
                                     "%d: '%s'" % (where, len(files), value))
            articulated.append(ArticulatedSpec(files[0], files[1], files[2], structure_id_from_clones(files[1]),
                                               where))
            continue
        if name in UNSUPPORTED_LATER_OPTIONS:
            raise UserInputError(later_feature_refusal(where, "option '%s' (unsupported here)" % name,
                                                       unsupported_feature(name)))
        if name not in OPTION_TABLE:
            close = difflib.get_close_matches(name, list(OPTION_TABLE) + ['structure', 'obstacle'], n=1)
            hint = " (did you mean '%s'?)" % close[0] if close else ''
            raise UserInputError("%s: unknown option '%s'%s" % (where, name, hint))
        values[name] = _convert(OPTION_TABLE[name].kind, name, value, where)
        if name in lines:
            repeated.append("%s: option '%s' repeats line %d; the later value is used (remove one of the lines)"
                            % (where, name, lines[name]))
        lines[name] = number
    options = Options(input_file, values, lines, structures, obstacles)
    options.articulated = articulated
    check_articulated(options)
    check_options(options, program)
    check_periodic_box(options)
    check_hydrogrid(options, program)
    options.warnings = repeated + unused_option_warnings(options, program)
    return options


def usage_tags(program, scheme):
    """The usage tags (see OPTION_TABLE) that a run of ``program`` with ``scheme`` has."""
    if program is None:
        program = 'static' if scheme in STATIC_SCHEMES else 'dynamic'
    tags = {program}
    entry = scheme_entry(scheme)
    if program == 'dynamic' and entry is not None:
        for tag, needed in (('stochastic', entry.kind == 'stochastic'), ('rollers', entry.rollers),
                            ('lubrication', entry.lubrication)):
            if needed:
                tags.add(tag)
    return tags


def is_used(name, program, scheme):
    """True when option ``name`` changes a run of ``program`` (None: as the scheme suggests) with ``scheme``."""
    return bool(usage_tags(program, scheme) & set(OPTION_TABLE[name].used_by))


def unused_options(options, program):
    """Names of the options the file sets that a run of ``program`` does not use (table order)."""
    phoretic = any(spec.laplace_file for spec in options.structures + options.obstacles)  # domain: wall images
    return [name for name in OPTION_TABLE
            if options.is_set(name) and OPTION_TABLE[name].used_by and not is_used(name, program, options.scheme)
            and not (name == 'domain' and phoretic)]


_USERS = {'static': 'the static problems', 'dynamic': 'the dynamic schemes', 'stochastic': 'the stochastic schemes',
          'rollers': 'the roller schemes', 'mcmc': 'the Monte Carlo sampler',
          'lubrication': 'the lubrication schemes'}


def unused_option_warnings(options, program=None):
    """Messages for options the file sets that the program reading it does not use (the ``used_by`` column).

    For the Monte Carlo program the parser makes only the "no effect"
    messages: the sampler logs its unused options in one line
    (``unused_options(options, 'mcmc')``).
    """
    messages = []
    for name in OPTION_TABLE:
        if options.is_set(name) and not OPTION_TABLE[name].used_by:
            messages.append("%s: option '%s' is accepted for compatibility with the published input files but "
                            "has no effect in this version (see doc/options.md)" % (options.where(name), name))
    if program == 'mcmc':
        return messages
    unused = unused_options(options, program)
    read_by_user = names_read_by_user_file(os.getcwd()) if unused else set()
    for name in unused:
        if name in read_by_user:  # a hook keyword that the user's functions read (Multi_Blob_Two_Rollers)
            continue
        used_by = OPTION_TABLE[name].used_by
        extra = {'domain': ' (the wall is chosen by the mobility implementations: names ending in _no_wall are '
                           'free space)',
                 'omega_one_roller': ' and by the functions of a user_defined_functions.py that read it (none '
                                     'here)'}.get(name, '')
        fix = 'choose a stochastic scheme or remove the line' if 'stochastic' in used_by else 'remove the line'
        messages.append("%s: option '%s' is ignored by scheme '%s' (it is used by %s only)%s; %s"
                        % (options.where(name), name, options.scheme,
                           ' and '.join(_USERS[tag] for tag in used_by), extra, fix))
    return messages


# The user's override file of the run directory (multi_bodies.solver.physics.USER_FILE; named here, a floor below).
USER_FILE = 'user_defined_functions.py'


def names_read_by_user_file(directory):
    """The string constants of ``directory``/user_defined_functions.py (the option names its functions may read
    from their keywords, ``kwargs.get('omega_one_roller')``); an empty set when there is no such readable file.

    Every hook receives the options of ``physics_keywords`` as keywords, so an option that a scheme does not use
    still changes a run whose user functions read it: its "ignored by scheme" warning is not given."""
    import ast
    path = os.path.join(directory, USER_FILE)
    if not os.path.isfile(path):
        return set()
    try:
        with open(path, encoding='utf-8', errors='replace') as f:
            tree = ast.parse(f.read())
    except (SyntaxError, ValueError, OSError):  # the hook loader reports a broken file
        return set()
    return {node.value for node in ast.walk(tree) if isinstance(node, ast.Constant) and isinstance(node.value, str)}


def check_options(options, program=None):
    """Check the options against their rules in OPTION_TABLE; raise UserInputError naming file, line and fix.

    ``program`` None: the general rule of every option (what the parser
    checks when it does not know the program).  A program name ('dynamic',
    'static', 'mcmc'): the options that program uses (and ``scheme``), each
    by its stricter ``program_rules`` entry first (e.g. ``dt`` > 0 for
    'dynamic'), then by its general rule.  Values that parse but make no
    sense are caught here, with the line, not deep in a solver.
    """
    for name, option in OPTION_TABLE.items():
        value = getattr(options, name)
        if value is None:
            continue
        if program is not None:
            if name != 'scheme' and not is_used(name, program, options.scheme):
                continue
            if name == 'scheme' and program == 'mcmc':
                continue
        check_value(name, value, options.where(name), program)


def check_value(name, value, where=None, program=None):
    """Check one option's value against its row of OPTION_TABLE (the program's stricter rule first).

    The one check of an option's range or choices: ``check_options`` applies it to a parsed input, and
    code that takes the value through its Python API (a scheme made directly) applies it too.
    ``where`` names the file and line (default the option's name).  Raises UserInputError.
    """
    option = OPTION_TABLE[name]
    rules = [option.rule] if program is None else [option.program_rules.get(program), option.rule]
    for rule in rules:
        if rule is not None and not rule.allows(value):
            known = rule is not option.rule and option.rule is not None and option.rule.allows(value)
            raise UserInputError(rule.message(where or name, name, value, known=known))


def check_articulated(options):
    """Articulated bodies need an articulated scheme (an articulated scheme moves plain bodies too, as published)."""
    lines = options.articulated
    if lines and options.scheme not in ARTICULATED_SCHEMES + STATIC_SCHEMES:
        raise UserInputError("%s: scheme '%s' cannot move articulated bodies (the 'articulated' line %s); use %s"
                             % (options.where('scheme'), options.scheme, lines[0].where,
                                ', '.join(ARTICULATED_SCHEMES)))


def check_hydrogrid(options, program=None):
    """call_HydroGrid (doc/analysis.md): a periodic xy box, cells >= 1, 0 <= i0 <= i1 in green_particles."""
    if not options.call_HydroGrid or program not in (None, 'dynamic'):
        return
    if min(options.periodic_length[:2]) <= 0:
        raise UserInputError('%s: call_HydroGrid needs a periodic box in the xy plane (periodic_length Lx Ly 0 with '
                             'Lx, Ly > 0)' % options.where('periodic_length'))
    if min(options.cells) < 1:
        raise UserInputError('%s: cells must be two integers >= 1' % options.where('cells'))
    if not 0 <= options.green_particles[0] <= options.green_particles[1]:
        raise UserInputError('%s: green_particles i0 i1 needs 0 <= i0 <= i1' % options.where('green_particles'))


def check_periodic_box(options):
    """A periodic z axis needs free space: above a wall it has no meaning (SPEC §8)."""
    if options.periodic_length[2] <= 0 or options.mobility_vector_prod_implementation == 'spectral':
        return  # the spectral product's geometry is checked with its options (multi_bodies.solver.periodic)
    implementations = (options.mobility_vector_prod_implementation, options.mobility_blobs_implementation)
    wall = any(not name.endswith('_no_wall') for name in implementations)
    if moves_rollers(options.scheme) and options.domain != 'no_wall':
        wall = True
    if wall:
        raise UserInputError(
            "%s: periodic_length along z is %g, but the simulation has a wall at z = 0; set the third value to 0, "
            "or choose free space (mobility implementations ending in _no_wall%s)"
            % (options.where('periodic_length'), options.periodic_length[2],
               ', domain no_wall' if moves_rollers(options.scheme) else ''))


def read_input_file(path, program=None):
    """Read and validate the input file at ``path`` for ``program`` (see ``parse_input_text``); returns ``Options``.

    Warnings about accepted but doubtful lines are printed on standard error.
    """
    text = read_text_file(path, 'input file', 'give the input file with --input-file')
    options = parse_input_text(text, path, program)
    for message in options.warnings:
        warn_user(message)
    return options


# The table's defaults as one Options value: a function of the package that takes an option as a keyword reads its
# default here (``DEFAULTS.solver_tolerance``), never writes it again (tests/test_option_defaults.py checks it).
DEFAULTS = options_with()
