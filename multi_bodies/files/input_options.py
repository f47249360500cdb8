"""Reader of the input file of the scripts: typed options with defaults.

Format: one option per line, ``name value``; everything
after a ``#`` is a comment; blank lines are skipped; a repeated option
replaces the earlier one, except ``structure``, of which every line is kept
(one per body type, in order).

Unlike the published code, every value is checked when it is read: an
unknown option, a value of the wrong type or a malformed ``structure`` line
raises ``utils.UserInputError`` naming the file, the line and what was
expected.  Options that only later versions of the published code know are
refused as unsupported rather than silently ignored (SPEC decision 9).
"""
import difflib
import math
import os
from collections import namedtuple

from utils import UserInputError, read_text_file, warn_user


# name -> (kind, default).  Kinds: str, int, float, floats3, grid9, bool, optional_str, optional_int.
OPTION_TABLE = {
    'scheme': ('str', 'deterministic_forward_euler'),
    'n_steps': ('int', 0),
    'initial_step': ('int', 0),
    'n_save': ('int', 1),
    'n_relaxation': ('int', 0),
    'dt': ('float', 0.0),
    'eta': ('float', 1.0),
    'g': ('float', 1.0),
    'blob_radius': ('float', 1.0),
    'tracer_radius': ('float', 0.0),
    'kT': ('float', 1.0),
    'output_name': ('str', 'run'),
    'random_state': ('optional_str', None),
    'seed': ('optional_int', None),
    'repulsion_strength_wall': ('float', 1.0),
    'debye_length_wall': ('float', 1.0),
    'repulsion_strength': ('float', 1.0),
    'debye_length': ('float', 1.0),
    'mobility_blobs_implementation': ('str', 'python'),
    'mobility_vector_prod_implementation': ('str', 'python'),
    'blob_blob_force_implementation': ('str', 'None'),
    'body_body_force_torque_implementation': ('str', 'None'),
    'solver_tolerance': ('float', 1e-8),
    'rf_delta': ('float', 1e-3),
    'save_clones': ('str', 'one_file_per_step'),
    'periodic_length': ('floats3', (0.0, 0.0, 0.0)),
    'omega_one_roller': ('floats3', (0.0, 0.0, 0.0)),
    'free_kinematics': ('bool', True),
    'domain': ('str', 'single_wall'),
    'update_PC': ('int', 1),
    'plot_velocity_field': ('grid9', None),
    'force_file': ('optional_str', None),
    'velocity_file': ('optional_str', None),
    'save_body_mobility': ('bool', False),
    'save_blobs_mobility': ('bool', False),
    'save_velocities': ('bool', False),
    'save_vtk': ('bool', False),
    'slip_file': ('optional_str', None),
    'structure_names': ('optional_str', None),
    # Monte Carlo sampler only (many_bodyMCMC, doc/mcmc.md); 0 step sizes select the published defaults
    'mcmc_move': ('str', 'all_bodies'), 'mcmc_energy_implementation': ('str', 'auto'),
    'max_translation': ('float', 0.0), 'max_angle_shift': ('float', 0.0),
    'n_burn_in': ('int', 0), 'target_acceptance': ('float', 0.3),
}

# Options of later versions of the published code that this package does not implement.
UNSUPPORTED_LATER_OPTIONS = (
    'tilt_angle', 'obstacle', 'articulated', 'repulsion_strength_firm', 'firm_delta',
    'hydro_interactions', 'call_HydroGrid', 'sample_HydroGrid', 'save_HydroGrid',
    'green_particles', 'cells', 'domType', 'Lub_Cut', 'zmin', 'zmax',
    'nonlinear_solver_tolerance', 'slip_length', 'plot_velocity_field_shell',
    'save_HydroGrid_cells', 'hydrodynamic_radius', 'mu', 'vacf', 'stiffness_wall',
)

StructureSpec = namedtuple('StructureSpec', ['vertex_file', 'clones_file', 'slip_file', 'ID', 'where'])
StructureSpec.__doc__ = """One ``structure`` line: file names (relative to the working directory),
the structure ID (clones file name without directory and ``.clones``) and
``where`` ("file, line n") for error messages."""


class Options:
    """Typed options of one input file.

    Every name of ``OPTION_TABLE`` is an attribute (defaults filled in);
    ``structures`` is the list of ``StructureSpec`` in input order;
    ``input_file`` the path read; ``where(name)`` says on which line an
    option was set ("<file>, line <n>", or "<file> (default)");
    ``warnings`` the messages about accepted but doubtful lines (printed by
    ``read_input_file``).
    """

    def __init__(self, input_file, values, lines, structures):
        self.input_file = input_file
        self._lines = dict(lines)
        self.structures = list(structures)
        self.warnings = []
        for name, (kind, default) in OPTION_TABLE.items():
            setattr(self, name, values.get(name, default))

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
    if kind == 'floats3':
        try:
            numbers = tuple(finite(w, 'three numbers') for w in words)
        except UserInputError:
            raise
        except ValueError:
            fail('three numbers')
        if len(numbers) != 3:
            fail('three numbers')
        return numbers
    if kind == 'grid9':
        expected = 'nine values x0 x1 Nx y0 y1 Ny z0 z1 Nz (Nx, Ny, Nz positive integers, x0 < x1, ...)'
        if len(words) != 9:
            fail(expected)
        try:
            grid = []
            for axis in range(3):
                low, high = finite(words[3 * axis], expected), finite(words[3 * axis + 1], expected)
                cells = int(words[3 * axis + 2])
                if cells < 1 or not high > low:
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


def parse_input_text(text, input_file='<input>'):
    """Parse the text of an input file into ``Options`` (see module docstring)."""
    values, lines, structures, repeated = {}, {}, [], []
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
        if name == 'structure':
            files = value.split()
            if len(files) not in (2, 3):
                raise UserInputError(
                    "%s: 'structure' expects two or three file names (vertex clones [slip]), got %d: '%s'"
                    % (where, len(files), value))
            slip = files[2] if len(files) == 3 else None
            structures.append(StructureSpec(files[0], files[1], slip,
                                            structure_id_from_clones(files[1]), where))
            continue
        if name in UNSUPPORTED_LATER_OPTIONS:
            raise UserInputError(
                "%s: option '%s' belongs to a later version of the published code and is unsupported "
                "here; remove the line (see doc/static_problems.md for the options we support)" % (where, name))
        if name not in OPTION_TABLE:
            close = difflib.get_close_matches(name, list(OPTION_TABLE) + ['structure'], n=1)
            hint = " (did you mean '%s'?)" % close[0] if close else ''
            raise UserInputError("%s: unknown option '%s'%s" % (where, name, hint))
        values[name] = _convert(OPTION_TABLE[name][0], name, value, where)
        if name in lines:
            repeated.append("%s: option '%s' repeats line %d; the later value is used (remove one of the lines)"
                            % (where, name, lines[name]))
        lines[name] = number
    options = Options(input_file, values, lines, structures)
    check_ranges(options)
    check_periodic_box(options)
    options.warnings = repeated + unused_option_warnings(options)
    return options


STATIC_SCHEMES = ('body_mobility', 'mobility', 'resistance')
# Largest magnitude of a number option: its square still fits in a double.
LARGEST_VALUE = 1e150
# eta and blob_radius beyond these bounds make eta a^3 (rotational resistance) over- or underflow.
SCALE_RANGE = (1e-50, 1e50)
ROLLER_ONLY_OPTIONS = ('domain', 'omega_one_roller', 'free_kinematics')
# Options of the published input files that are read (and checked) but change nothing in this version;
# remove a name here when a scheme starts to use it (doc/options.md lists them too).
NO_EFFECT_OPTIONS = ('n_relaxation', 'save_velocities', 'slip_file', 'structure_names')
STOCHASTIC_ONLY_OPTIONS = ('kT', 'rf_delta', 'update_PC')


def unused_option_warnings(options):
    """Messages for options that the chosen scheme does not use although the file sets them."""
    messages = []
    scheme = options.scheme
    if 'rollers' not in scheme:
        for name in ROLLER_ONLY_OPTIONS:
            if options.is_set(name):
                extra = (' (the wall is chosen by the mobility implementations: names ending in _no_wall are '
                         'free space)' if name == 'domain' else '')
                messages.append("%s: option '%s' is used by the roller schemes only and is ignored by scheme "
                                "'%s'%s; remove the line" % (options.where(name), name, scheme, extra))
    for name in NO_EFFECT_OPTIONS:
        if options.is_set(name):
            messages.append("%s: option '%s' is accepted for compatibility with the published input files but "
                            "has no effect in this version (see doc/options.md)" % (options.where(name), name))
    if scheme.startswith('deterministic') or scheme in STATIC_SCHEMES:
        for name in STOCHASTIC_ONLY_OPTIONS:
            if options.is_set(name):
                messages.append("%s: option '%s' is ignored by scheme '%s', which has no thermal noise; choose a "
                                "stochastic scheme or remove the line" % (options.where(name), name, scheme))
    return messages


def check_ranges(options):
    """Values that parse but make no sense: caught here, with the line, not deep in a solver."""
    for name in ('eta', 'blob_radius'):
        value = getattr(options, name)
        if not SCALE_RANGE[0] <= value <= SCALE_RANGE[1]:
            raise UserInputError('%s: %s must be positive, between %g and %g (beyond that eta a^3 over- or '
                                 'underflows in double precision; rescale the units), got %g'
                                 % (options.where(name), name, SCALE_RANGE[0], SCALE_RANGE[1], value))
    if not 0.0 < options.solver_tolerance < 1.0:
        raise UserInputError('%s: solver_tolerance is a relative tolerance between 0 and 1 (e.g. 1e-8), got %g'
                             % (options.where('solver_tolerance'), options.solver_tolerance))
    for name in ('debye_length', 'debye_length_wall'):
        if not getattr(options, name) > 0.0:
            raise UserInputError('%s: %s must be positive (the repulsion laws divide by it), got %g'
                                 % (options.where(name), name, getattr(options, name)))
    if options.tracer_radius < 0.0:
        raise UserInputError('%s: tracer_radius must be >= 0 (0 gives the point velocity), got %g'
                             % (options.where('tracer_radius'), options.tracer_radius))
    if options.n_steps < 0:
        raise UserInputError('%s: n_steps must be >= 0 (the index of the last step), got %d'
                             % (options.where('n_steps'), options.n_steps))


def check_periodic_box(options):
    """A periodic z axis needs free space: above a wall it has no meaning (SPEC §8)."""
    if options.periodic_length[2] <= 0:
        return
    implementations = (options.mobility_vector_prod_implementation, options.mobility_blobs_implementation)
    wall = any(not name.endswith('_no_wall') for name in implementations)
    if 'rollers' in options.scheme and options.domain != 'no_wall':
        wall = True
    if wall:
        raise UserInputError(
            "%s: periodic_length along z is %g, but the simulation has a wall at z = 0; set the third value to 0, "
            "or choose free space (mobility implementations ending in _no_wall%s)"
            % (options.where('periodic_length'), options.periodic_length[2],
               ', domain no_wall' if 'rollers' in options.scheme else ''))


def read_input_file(path):
    """Read and validate the input file at ``path``; returns ``Options``.

    Warnings about accepted but doubtful lines are printed on standard error.
    """
    text = read_text_file(path, 'input file', 'give the input file with --input-file')
    options = parse_input_text(text, path)
    for message in options.warnings:
        warn_user(message)
    return options
