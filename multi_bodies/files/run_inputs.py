"""The files a run reads besides its input file, by kind, and the digest of their content (floor 3).

A restart is exact only when everything the trajectory depends on is what
it was when the record was written: the options (``OPTION_TABLE``'s
``dynamics`` column) and the content of every file the run reads at a
restart.  :func:`restart_inputs` lists those files from the options, so the
restart fingerprint (``multi_bodies.run.restart_records.run_fingerprint``)
covers each of them; ``FILE_KINDS`` says, for every kind of file a program
reads, whether a restart depends on it and why not when it does not.  A data
file that an override source reads (a table of parameters) cannot be seen
from the options: the source declares it, ``data_files = ['parameters.dat']``
at module level, and it is covered like the source itself.
"""
import hashlib
import os

from utils import UserInputError, read_text_file

# The override sources a run imports from its run directory (multi_bodies.solver.physics.USER_FILE and
# USER_PYCUDA_FILE, many_bodyMCMC.mcmc_energy.USER_POTENTIAL_FILE and GPU_POTENTIAL_FILE; a test checks that the
# names agree, this floor cannot import theirs).
OVERRIDE_FILES = ('user_defined_functions.py', 'forces_pycuda_user_defined.py', 'user_defined_potentials.py',
                  'potential_pycuda_user_defined.py')
# A folder's own copy of the published override module, which a run in the published spectral form reads
# (multi_bodies.solver.user_hooks.FOLDER_MODULE_COPY); the package's own module beside the scripts is not one.
FOLDER_MODULE_FILE = 'multi_bodies_functions.py'
PACKAGE_MODULE_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), FOLDER_MODULE_FILE)

# kind -> True when a restart reads it (its content is in the fingerprint), else why a change cannot alter the
# continuation.
FILE_KINDS = {
    'vertex': True,         # blob positions (and radii) of a structure, obstacle or articulated body
    'slip': True,           # active slip of the blobs of a structure line
    'velocity': True,       # prescribed velocities of the bodies of a structure line
    'list_vertex': True,    # vertex files of the bodies of an articulated line
    'const': True,          # joints of an articulated line (and their expressions of t)
    'override': True,       # user_defined_functions.py and the other override sources of the run directory, and a
                            # folder's own multi_bodies_functions.py where it is read
    'override data': True,  # the data files an override source declares it reads (``data_files = [...]``)
    'Laplace': True,        # phoretic bodies: normals, reaction and emitting rates, surface mobilities, weights
    'slip_length': True,    # partial-slip surfaces: normals, slip lengths, weights
    'clones': 'read at step 0 only: a restart reads the saved snapshot instead (checked against its record)',
    'force': 'read by the static problems only (force_file of scheme mobility), never by a run that restarts',
    'random_state': 'read at step 0 only: a restart continues the generator state of its record',
}


def file_digest(path):
    """'sha256 <first 16 hex digits>' of the bytes of ``path`` (read in chunks: any size), 'missing', or 'not a
    regular file' (a FIFO or device is never read: it could block for ever)."""
    import stat
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return 'not a regular file'
        digest = hashlib.sha256()
        with open(path, 'rb') as f:
            for chunk in iter(lambda: f.read(1 << 20), b''):
                digest.update(chunk)
        return 'sha256 %s' % digest.hexdigest()[:16]
    except (OSError, ValueError):  # ValueError: a NUL byte in the name
        return 'missing'


DATA_FILES_NAME = 'data_files'  # the list an override source declares: the files its hooks read
OVERRIDE_SOURCE_BYTES = 1 << 24  # an override source is a Python file of a few kilobytes


def declared_data_files(path):
    """The names an override source at ``path`` declares in a module-level ``data_files = ['a.dat', ...]`` (file
    names relative to the run directory), read from its text without running it.

    Raises UserInputError naming the file and line when ``data_files`` is not a list (or tuple) of strings written
    as literals, so that what the restart fingerprint covers never depends on running the file."""
    import ast
    try:
        if os.path.getsize(path) > OVERRIDE_SOURCE_BYTES:
            return []
        with open(path, 'rb') as f:
            tree = ast.parse(f.read(), filename=path)
    except (OSError, SyntaxError, ValueError, RecursionError, MemoryError):
        return []  # the hooks loader names what is wrong with the file
    found = []
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) and node.value is not None else []
        if not any(isinstance(t, ast.Name) and t.id == DATA_FILES_NAME for t in targets):
            continue
        try:
            value = ast.literal_eval(node.value)
        except (ValueError, TypeError, SyntaxError, RecursionError, MemoryError):
            value = None
        if not (isinstance(value, (list, tuple)) and all(isinstance(v, str) and v and '\x00' not in v
                                                          for v in value)):
            raise UserInputError('%s, line %d: %s must be a list of file names written as text (for example '
                                 "data_files = ['parameters.dat']): the restart fingerprint reads it without running "
                                 'the file' % (path, node.lineno, DATA_FILES_NAME))
        found = list(value)
    return found


def _list_vertex_names(path):
    """The vertex files a ``.list_vertex`` file names (one per line, ``#`` comments); [] when unreadable."""
    try:
        text = read_text_file(path, 'list_vertex file', 'give the path relative to the run directory')
    except UserInputError:
        return []
    return [name for name in (line.split('#', 1)[0].strip() for line in text.splitlines()) if name]


def restart_inputs(options, directory):
    """(kind, name, path) of every file whose content a restart of ``options`` depends on, in a fixed order.

    ``name`` is the file as the input names it (an override source: its file name), ``path`` where it is read;
    ``directory``: the run directory (where the override sources are imported from).  Each file appears once.
    """
    found = []
    specs = list(options.structures) + list(options.obstacles)
    for spec in specs:
        found.append(('vertex', spec.vertex_file))
        if spec.slip_file is not None:
            found.append(('slip', spec.slip_file))
        if spec.velocity_file is not None:
            found.append(('velocity', spec.velocity_file))
        if spec.laplace_file is not None:  # phoretic bodies: normals, rates, mobilities, weights
            found.append(('Laplace', spec.laplace_file))
        if spec.slip_length_file is not None:  # partial-slip surfaces: normals, slip lengths, weights
            found.append(('slip_length', spec.slip_length_file))
    for spec in options.articulated:
        found.append(('list_vertex', spec.list_vertex_file))
        found.append(('const', spec.const_file))
        found.extend(('vertex', name) for name in _list_vertex_names(spec.list_vertex_file))
    for name in OVERRIDE_FILES + (FOLDER_MODULE_FILE,):
        path = os.path.join(directory, name)
        if name == FOLDER_MODULE_FILE and os.path.isfile(path) and os.path.samefile(path, PACKAGE_MODULE_FILE):
            continue
        if os.path.isfile(path):
            found.append(('override', name, path))
            found.extend(('override data', data, os.path.join(directory, data))
                         for data in declared_data_files(path))
    unique, seen = [], set()
    for entry in found:
        kind, name, path = entry if len(entry) == 3 else (entry[0], entry[1], entry[1])
        if name not in seen:
            seen.add(name)
            unique.append((kind, name, path))
    return unique
