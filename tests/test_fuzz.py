"""Fuzzer of the two scripts (issue 10): mutated copies of the example files must never crash.

Each case picks a scene and applies one to three mutations to its files
(deleted, duplicated and swapped lines; truncated numbers; NaN, inf, huge,
tiny and negative values; wrong counts; binary garbage; other encodings;
other option values), then runs BOTH scripts on the result:

* boomerang (weight 3): the shipped ``inputfile_dynamic.dat`` (with
  ``n_steps 2``), ``inputfile.dat`` (mobility and velocity field),
  ``inputfile_body_mobility.dat``, a resistance problem with a velocity file,
  and the boomerang, shell, force and velocity files they read;
* squirmer: a 42-blob shell with its shipped ``.slip`` file, dynamic and
  mobility problem;
* rollers: the shipped ``inputfile_rollers.dat`` (2 steps) and the mobility
  problem of its four single-blob bodies;
* articulated: a chain of two one-blob bodies, its ``.list_vertex`` and its
  ``.const`` with expressions of t (issue 27), dynamic problem;
* driven: a free body and a body of prescribed velocity (a velocity file on
  its structure line, issue 27), dynamic and mobility problem.

The scripts run in-process, exactly as their ``__main__`` block runs them
(``utils.fail_cleanly(main)``), because a child process costs a second of
imports per case.  The folder already holds the outputs of an earlier run of
every unmutated input.  Asserted for every run:

* exit status 0, 1 or 2, and no exception escaping ``main`` (a traceback);
* with status 2, an ``error:`` message naming a file or an option;
* with status 2, every file written by the earlier run unchanged, byte for byte;
* for the classified cases (one in four: one mutation of known meaning of an input file,
  ``KNOWN_REFUSED`` and ``HARMLESS``): a negative dt, an unknown option, a missing
  structure file, a non-numeric eta or an unknown scheme is refused (status 2, the
  message names the input file, the line and the option or file), and an added
  comment or changed whitespace runs (status 0).

A second fuzzer (issue 27) forges restart records: one field of the record of
a dynamic (``one_file_per_step`` and ``one_file``), articulated, Monte Carlo,
Adams-Bashforth, phoretic or roller run replaced by a value of another type,
sign, size or shape, the checksum recomputed; the fields a scene's records do
not have are forged too (added: ``KNOWN_FIELDS``, issue 48).  The restart must
end in one ``error:`` line (exit 2) or run.

Findings in files owned elsewhere are listed in ``KNOWN_FOREIGN`` (each
reproduced by a strict xfail test at the end); any other finding fails.
CI runs ``RMB_FUZZ_EXAMPLES`` cases (default 300) with a fixed seed
(hypothesis ``derandomize``).  A longer run, with new random cases each time,
that collects every finding instead of stopping at the first::

    RMB_FUZZ_EXAMPLES=3000 RMB_FUZZ_RANDOM=1 RMB_FUZZ_COLLECT=1 python3 -m pytest -q tests/test_fuzz.py -s

prints the number of cases and of each outcome at the end.
"""
import collections
import os
import re
import shutil
import time
import traceback
from pathlib import Path

import pytest

hypothesis = pytest.importorskip('hypothesis', reason='hypothesis is a test extra: pip install -e .[test]')
from hypothesis import HealthCheck, assume, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from multi_bodies.files.input_options import OPTION_TABLE, parse_input_text  # noqa: E402
from utils import UserInputError  # noqa: E402

from run_scenes import (REPO_ROOT, add_generated_inputs, copy_scene, edit_input, run_in_process,  # noqa: E402
                        snapshot_files)

pytestmark = pytest.mark.fuzz

EXAMPLES = int(os.environ.get('RMB_FUZZ_EXAMPLES', '300'))
RANDOM = os.environ.get('RMB_FUZZ_RANDOM', '') not in ('', '0')

# Scenes: (dynamic input, static inputs, files a case may mutate).  The boomerang scene is the shipped
# examples; the others are made from shipped files by run_scenes.add_generated_inputs.
SCENES = {
    'boomerang': ('inputfile_dynamic.dat', ('inputfile.dat', 'inputfile_body_mobility.dat', 'inputfile_resistance.dat'),
                  ('inputfile_dynamic.dat', 'inputfile.dat', 'inputfile_body_mobility.dat', 'inputfile_resistance.dat',
                   'Structures/boomerang_N_15.vertex', 'Structures/boomerang_N_15.clones',
                   'Structures/shell_N_12_Rg_1.vertex', 'Structures/shell_N_12_Rg_1.clones',
                   'Structures/force.dat', 'velocity.dat')),
    'squirmer': ('inputfile_squirmer.dat', ('inputfile_squirmer_mobility.dat',),
                 ('inputfile_squirmer.dat', 'inputfile_squirmer_mobility.dat',
                  'Structures/shell_N_42_Rg_0_8912_Rh_1.vertex', 'Structures/squirmer.clones',
                  'Structures/shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip')),
    'rollers': ('inputfile_rollers.dat', ('inputfile_rollers_mobility.dat',),
                ('inputfile_rollers.dat', 'inputfile_rollers_mobility.dat', 'Structures/blob.vertex',
                 'Structures/four_rollers.clones')),
    # issue 27: the files of an articulated chain (.list_vertex, .const with expressions of t) and a body of
    # prescribed velocity (the fourth file of a structure line), written by add_chain_and_driven_scenes
    # (the static problem of the chain scene is the rollers' one: a mobility problem with an articulated line
    # ended in an AttributeError at commit 37754c1, in a file under refactoring; reported with issue 27)
    'articulated': ('inputfile_chain.dat', ('inputfile_rollers_mobility.dat',),
                    ('inputfile_chain.dat', 'Structures/chain.list_vertex', 'Structures/chain.const',
                     'Structures/chain.clones', 'Structures/blob.vertex')),
    'driven': ('inputfile_driven.dat', ('inputfile_driven_mobility.dat',),
               ('inputfile_driven.dat', 'inputfile_driven_mobility.dat', 'Structures/driven.velocity',
                'Structures/driven.clones',
                'Structures/free.clones')),
}
SCENE_WEIGHTS = ['boomerang'] * 3 + ['squirmer', 'rollers', 'articulated', 'driven']
INPUTS = sorted({name for _, statics, files in SCENES.values() for name in files if name.startswith('inputfile')})
DYNAMIC_INPUTS = {dynamic for dynamic, _, _ in SCENES.values()}
MUTABLE = sorted({name for _, _, files in SCENES.values() for name in files})

# What a status-2 message must name: a file of the scene, or an option (as a whole word; the short names
# g, dt, kT, eta only as "'g'" or "g must", so that "e.g." does not count).
NAMEABLE = re.compile('|'.join(
    [re.escape(os.path.basename(name)) for name in MUTABLE]
    + [r'\b%s\b' % re.escape(name) for name in OPTION_TABLE if len(name) > 3]
    + [r"'%s'|\b%s must" % (name, name) for name in OPTION_TABLE if len(name) <= 3]
    + [r'\bstructure\b', 'input file', 'user_defined_functions']))

NUMBERS = ['nan', 'NaN', 'inf', '-inf', '1e308', '1e400', '-1e400', '1e150', '1e20', '1e-320', '-1', '-0', '0',
           '-2.5', '99999', '-99999', '9223372036854775808', '1e', '0x10', '1,5', '.', '+', '--1', '1e-5']
WORDS = ['True', 'False', 'None', 'none', 'python', 'C++', 'C++_no_wall', 'python_no_wall', 'pycuda', 'numba',
         'auto', 'one_file', 'mobility', 'resistance', 'body_mobility', 'deterministic_forward_euler',
         'deterministic_forward_euler_rollers', 'stochastic_first_order_RFD', 'data/other', 'no_wall', 'a b',
         '', '#', 'Structures', 'Structures/force.dat', 'Structures/force.dat/run', '\u00e9t\u00e9', '\x00']
# issue 48: words no user means but a file can hold: a 100 kB token, an output name 2,000 folders deep
WORDS += ['y' * 100000, '/'.join(['d'] * 2000) + '/run', 'data/' + 'z' * 300, '/proc/run']
ENCODINGS = ['utf-16', 'utf-32', 'latin-1', 'cp1252', 'utf-8-sig']
# issue 48: hostile lines appended to an input file (each bounded up front, or refused, in one line)
HOSTILE_LINES = ['call_HydroGrid True\ncells 100000 100000\nperiodic_length 30 30 0',
                 'nonlinear_solver_tolerance 1e-17', 'save_concentration True', 'restart_inexact True',
                 'initial_step 1', 'random_state Structures/force.dat']
# issue 48: a file replaced by something that is not a file (path mutations), and the extra paths they may hit
PATH_KINDS = ['fifo', 'dangling link', 'folder']
PATH_ONLY = ['user_defined_functions.py', 'data/run.lock', 'data/chain.lock']
LIMITS = {'n_steps': 3, 'cells': 4000}


# ---------------------------------------------------------------------- mutations
def _lines(data):
    return data.split(b'\n')


def _number_tokens(line):
    """(start, end) byte spans of the tokens of a line that read as numbers."""
    spans, start = [], None
    for i, ch in enumerate(line + b' '):
        if ch in b' \t\r':
            if start is not None:
                token = line[start:i]
                try:
                    float(token)
                    spans.append((start, i))
                except ValueError:
                    pass
                start = None
        elif start is None:
            start = i
    return spans


def mutate(data, mutation):
    """Apply one mutation (a tuple drawn by ``mutations()``) to the bytes of a file."""
    kind, a, b, value = mutation
    lines = _lines(data)
    i, j = a % len(lines), b % len(lines)
    if kind == 'delete':
        del lines[i]
    elif kind == 'duplicate':
        lines.insert(i, lines[i])
    elif kind == 'swap':
        lines[i], lines[j] = lines[j], lines[i]
    elif kind in ('truncate', 'number'):
        candidates = [(n, span) for n, line in enumerate(lines) for span in _number_tokens(line)]
        if not candidates:
            return data
        n, (start, end) = candidates[a % len(candidates)]
        token = lines[n][start:end]
        new = token[:b % (len(token) + 1)] if kind == 'truncate' else value.encode()
        lines[n] = lines[n][:start] + new + lines[n][end:]
    elif kind == 'count':
        for n, line in enumerate(lines):
            words = line.split(b'#')[0].split()
            if words:
                lines[n] = line.replace(words[0], value.encode(), 1)
                break
    elif kind == 'word':  # the value of an option line (input files) or a whole token
        words = lines[i].split(b'#')[0].split()
        if len(words) >= 2:
            lines[i] = words[0] + b' ' + value.encode('utf-8')
        elif lines[i].strip():
            lines[i] = value.encode('utf-8')
    elif kind == 'garbage':
        position = a % (len(data) + 1)
        return data[:position] + value.encode('latin-1') + data[position:]
    elif kind == 'encoding':
        text = data.decode('utf-8', errors='replace')
        text = text[:a % (len(text) + 1)] + '\u00e9\u00b5' + text[a % (len(text) + 1):]
        return text.encode(value, errors='replace')
    elif kind == 'empty':
        return b''
    elif kind == 'known':
        return mutate_known(data, value)
    elif kind == 'hostile line':
        return data + b'\n' + value.encode() + b'\n'
    elif kind == 'huge token':  # a number or word of the file replaced by a megabyte of one character
        candidates = [(n, span) for n, line in enumerate(lines) for span in _number_tokens(line)]
        if not candidates:
            return data + b'\n' + b'w' * 10 ** 6
        n, (start, end) = candidates[a % len(candidates)]
        lines[n] = lines[n][:start] + value.encode() * 10 ** 6 + lines[n][end:]
    return b'\n'.join(lines)


def mutate_path(path, kind):
    """Replace ``path`` (a Path) by a FIFO, a dangling symbolic link or a folder."""
    if path.is_symlink() or path.exists():
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == 'fifo':
        os.mkfifo(str(path))
    elif kind == 'dangling link':
        path.symlink_to(path.parent / 'no_such_target')
    else:
        path.mkdir()


# Mutations of an input file whose meaning is known (a case holds one of them and nothing else): label ->
# (which scripts must refuse it: 'dynamic' or 'both'; what the message must name).  The refused ones must end
# with exit status 2 and an ``error:`` message naming the option or file; the harmless ones with exit 0.
KNOWN_REFUSED = {'negative dt': ('dynamic', 'dt'), 'unknown option': ('both', 'no_such_option'),
                 'missing file': ('both', 'missing_file.vertex'), 'non-numeric eta': ('both', 'eta'),
                 'unknown scheme': ('both', 'no_such_scheme')}
HARMLESS = ('comment added', 'whitespace')


def _replace_option(lines, name, value):
    pattern = re.compile(r'^\s*%s(\s|$)' % re.escape(name))
    found = [n for n, line in enumerate(lines) if pattern.match(line)]
    if found:
        lines[found[0]] = '%s %s' % (name, value)
    else:
        lines.append('%s %s' % (name, value))
    return lines


def mutate_known(data, label):
    """Apply the known mutation ``label`` (KNOWN_REFUSED or HARMLESS) to the bytes of an input file."""
    lines = data.decode('utf-8').split('\n')
    if label == 'negative dt':
        lines = _replace_option(lines, 'dt', '-0.01')
    elif label == 'unknown option':
        lines.insert(len(lines) // 2, 'no_such_option 1')
    elif label == 'missing file':
        n = next(n for n, line in enumerate(lines) if line.split()[:1] in (['structure'], ['articulated']))
        words = lines[n].split()
        lines[n] = ' '.join([words[0], 'Structures/missing_file.vertex'] + words[2:])
    elif label == 'non-numeric eta':
        lines = _replace_option(lines, 'eta', 'abc')
    elif label == 'unknown scheme':
        lines = _replace_option(lines, 'scheme', 'no_such_scheme')
    elif label == 'comment added':
        lines = ['# a comment added by the fuzzer'] + lines + ['   # and an indented one', '#']
    elif label == 'whitespace':
        lines = [re.sub(r'[ ]+', '\t ', line) + '  \t' if line.strip() else line for line in lines]
        lines = ['', '   '] + lines + ['', '\t']
    else:
        raise ValueError(label)
    return '\n'.join(lines).encode('utf-8')


def mutations():
    index = st.integers(0, 200)
    garbage = st.binary(min_size=1, max_size=12).map(lambda raw: raw.decode('latin-1'))
    return st.one_of(
        st.tuples(st.sampled_from(['delete', 'duplicate', 'swap', 'truncate']), index, index, st.just('')),
        st.tuples(st.just('number'), index, index, st.sampled_from(NUMBERS)),
        st.tuples(st.just('count'), index, index, st.sampled_from(['0', '-3', '1', '2', '3', '14', '16', '40',
                                                                    '1.5', 'x', '1e2'])),
        st.tuples(st.just('word'), index, index, st.sampled_from(WORDS + NUMBERS)),
        st.tuples(st.just('garbage'), index, index, garbage),
        st.tuples(st.just('encoding'), index, index, st.sampled_from(ENCODINGS)),
        st.tuples(st.just('empty'), index, index, st.just('')),
        st.tuples(st.just('hostile line'), index, index, st.sampled_from(HOSTILE_LINES)),
        st.tuples(st.just('huge token'), index, index, st.sampled_from(['9', 'q'])),
        st.tuples(st.just('path'), index, index, st.sampled_from(PATH_KINDS)),
    )


@st.composite
def cases(draw):
    """(edits, dynamic input, static input).  One case in four is classified: one known mutation
    (KNOWN_REFUSED or HARMLESS) of one of the two input files, and nothing else."""
    dynamic_input, static_inputs, files = SCENES[draw(st.sampled_from(SCENE_WEIGHTS))]
    static_input = draw(st.sampled_from(static_inputs))
    if draw(st.integers(0, 3)) == 0:
        label = draw(st.sampled_from(sorted(KNOWN_REFUSED) + list(HARMLESS)))
        target = draw(st.sampled_from([dynamic_input, static_input]))
        return [(target, ('known', 0, 0, label))], dynamic_input, static_input
    edits = draw(st.lists(st.tuples(st.sampled_from(list(files) + PATH_ONLY), mutations()), min_size=1, max_size=3))
    edits = [(name, mutation) for name, mutation in edits if name in files or mutation[0] == 'path']
    assume(edits)
    return edits, dynamic_input, static_input


def expected_outcome(kind, input_name, edits):
    """(exit status, names the message must contain) that a classified case promises for this run, or None.

    A refused mutation of the input file the script reads: status 2 and a message naming the input file,
    the line and the option or file (KNOWN_REFUSED).  A harmless mutation, or an input file left
    unmutated in a classified case: status 0.  Unclassified cases promise only what check_run checks.
    """
    if len(edits) != 1 or edits[0][1][0] != 'known':
        return None
    target, (_, _, _, label) = edits[0]
    if target != input_name or label in HARMLESS:
        return 0, ()
    scope, name = KNOWN_REFUSED[label]
    if scope == 'dynamic' and kind != 'dynamic':
        return None  # e.g. a negative dt in a static problem, which does not read dt
    return 2, (os.path.basename(input_name), 'line', name)


# ---------------------------------------------------------------------- the earlier run
COMMON_LINES = ('eta 1.0\nblob_radius 0.25\ng 1.0\ndt 0.01\nn_steps 2\nn_save 1\nsolver_tolerance 1e-8\n'
                'mobility_blobs_implementation python\nmobility_vector_prod_implementation python\n'
                'blob_blob_force_implementation python\nrepulsion_strength_wall 1.0\ndebye_length_wall 0.2\n')


def add_chain_and_driven_scenes(folder):
    """Inputs of the 'articulated' and 'driven' scenes (issue 27), beside the shipped ones."""
    structures = folder / 'Structures'
    (structures / 'chain.list_vertex').write_text('Structures/blob.vertex\nStructures/blob.vertex\n')
    (structures / 'chain.const').write_text('2\n1\n0 1 0.5 0 0 -0.5 0 0 0.5 0 0 -0.5 0 0.1*sin(t) 0 0 0 0 0 '
                                            '0.1*cos(t)\n')
    (structures / 'chain.clones').write_text('2\n0 0 3 1 0 0 0\n1 0 3 1 0 0 0\n')
    (structures / 'driven.velocity').write_text('0.2 0 0 0 0 0.1\n')
    (structures / 'driven.clones').write_text('1\n2.5 0 2.5 1 0 0 0\n')
    (structures / 'free.clones').write_text('1\n0 0 2.0 1 0 0 0\n')
    chain = 'articulated Structures/chain.list_vertex Structures/chain.clones Structures/chain.const\n'
    driven = ('structure Structures/blob.vertex Structures/free.clones\n'
              'structure Structures/blob.vertex Structures/driven.clones None Structures/driven.velocity\n')
    for name, scheme, lines, output in (
            ('inputfile_chain.dat', 'articulated_deterministic_forward_euler', chain, 'data/chain'),
            ('inputfile_driven.dat', 'deterministic_forward_euler', driven, 'data/driven'),
            ('inputfile_driven_mobility.dat', 'mobility', driven, 'data/driven_mobility')):
        (folder / name).write_text('scheme %s\n%soutput_name %s\n%s' % (scheme, COMMON_LINES, output, lines))
    return folder


@pytest.fixture(scope='module')
def earlier_run(tmp_path_factory):
    """The unmutated scene after one run of each script (its outputs must survive failed validations)."""
    folder = add_generated_inputs(copy_scene(tmp_path_factory.mktemp('fuzz') / 'earlier'))
    add_chain_and_driven_scenes(folder)
    edit_input(folder / 'inputfile_dynamic.dat', n_steps=2)
    edit_input(folder / 'inputfile_rollers.dat', n_steps=2, n_save=1)
    for dynamic_input, static_inputs, _ in SCENES.values():
        for kind, input_name in [('static', name) for name in static_inputs] + [('dynamic', dynamic_input)]:
            status, out, err = run_in_process(kind, folder, input_name)
            assert status == 0, (input_name, err)
    return folder


OUTCOMES = collections.Counter()
MESSAGES = collections.Counter()  # status-2 messages with names and numbers blanked out


def within_limits(folder):
    """False when a mutation made the scene expensive (a long run or a huge grid), which is not a mistake."""
    for name in INPUTS:
        if not (folder / name).is_file() or (folder / name).is_symlink():
            continue
        try:
            text = (folder / name).read_bytes().decode('utf-8')
            options = parse_input_text(text, name)
        except (UserInputError, UnicodeDecodeError):
            continue
        if name in DYNAMIC_INPUTS and options.n_steps - options.initial_step > LIMITS['n_steps']:
            return False
        if options.plot_velocity_field is not None:
            cells = 1
            for _, _, count in options.plot_velocity_field:
                cells *= count
            if cells > LIMITS['cells']:
                return False
    return True


class Finding(AssertionError):
    """One broken promise of a script: ``signature`` groups findings of the same cause."""

    def __init__(self, signature, detail):
        super().__init__('%s\n%s' % (signature, detail))
        self.signature = signature


def traceback_signature(kind, error):
    """'<script>: <exception type> in <file>:<function>' of the innermost frame inside the repository."""
    frames = [f for f in traceback.extract_tb(error.__traceback__) if f.filename.startswith(str(REPO_ROOT))
              and '/tests/' not in f.filename]
    where = ('%s:%s' % (os.path.relpath(frames[-1].filename, str(REPO_ROOT)), frames[-1].name)) if frames else '?'
    return '%s: %s in %s' % (kind, type(error).__name__, where)


def check_run(kind, folder, input_name, expected=None):
    """Run one script on the case; raises Finding when a promise of the module docstring is broken, or
    when ``expected`` (exit status, names the ``error:`` message must contain) is not met."""
    before = snapshot_files(folder / 'data')
    try:
        status, out, err = run_in_process(kind, folder, input_name)
    except Exception as error:  # what the user would have seen as a traceback
        raise Finding(traceback_signature(kind, error), ''.join(traceback.format_exception(error))[-3000:])
    OUTCOMES['%s exit %s' % (kind, status)] += 1
    if status not in (0, 1, 2):
        raise Finding('%s: exit status %r' % (kind, status), err[-3000:])
    if 'Traceback' in out + err:
        raise Finding('%s: traceback printed' % kind, err[-3000:])
    if status == 2:
        message = [line for line in err.splitlines() if line.startswith('error: ')]
        if message:
            MESSAGES[re.sub(r"'[^']*'|\S*\d\S*", '_', message[-1])[:110]] += 1
        if not message or not NAMEABLE.search(message[-1]):
            raise Finding('%s: status 2 without a message naming a file or option' % kind, err[-3000:])
        after = snapshot_files(folder / 'data')
        changed = sorted(name for name in before if after.get(name) != before[name])
        if changed:
            kinds = sorted({name.rsplit('.', 1)[-1] for name in changed})
            raise Finding('%s: earlier outputs changed by a failed validation (%s)' % (kind, ', '.join(kinds)),
                          '%s\nchanged: %s' % (message[-1], changed))
    if expected is not None:
        status_expected, names = expected
        last = ([line for line in err.splitlines() if line.startswith('error: ')] or [''])[-1]
        if status != status_expected or not all(name in last for name in names):
            raise Finding('%s: classified mutation gave exit %s, expected %s naming %s'
                          % (kind, status, status_expected, ', '.join(names) or 'nothing'), err[-3000:])
        OUTCOMES['classified %s, exit %d as expected' % ('refused' if status_expected == 2 else 'harmless',
                                                          status)] += 1
    return status


# Findings of earlier runs in files owned by others, now fixed (each reproduced by a test below):
# the static script wrote before validating, created the output folder itself, and let a singular blob
# mobility (a body at 1e20) through as a traceback.  Nothing is tolerated any more.
KNOWN_FOREIGN = ()
FINDINGS = collections.defaultdict(list)
COLLECT = os.environ.get('RMB_FUZZ_COLLECT', '') not in ('', '0')


def run_both(folder, dynamic_input, static_input, edits):
    for kind, input_name in (('dynamic', dynamic_input), ('static', static_input)):
        try:
            check_run(kind, folder, input_name, expected_outcome(kind, input_name, edits))
        except Finding as finding:
            FINDINGS[finding.signature].append('%s on %s after %r\n%s' % (kind, input_name, edits, finding))
            if not (COLLECT or finding.signature.startswith(KNOWN_FOREIGN)):
                raise


@settings(max_examples=EXAMPLES, derandomize=not RANDOM, deadline=None, database=None, print_blob=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.function_scoped_fixture])
@given(case=cases())
def test_scripts_survive_mutated_inputs(earlier_run, tmp_path_factory, case):
    edits, dynamic_input, static_input = case
    folder = tmp_path_factory.mktemp('case')
    shutil.rmtree(folder)
    shutil.copytree(earlier_run, folder)
    try:
        for name, mutation in edits:
            path = folder / name
            if mutation[0] == 'path':
                mutate_path(path, mutation[3])
            elif path.is_file() and not path.is_symlink():  # (a file a path mutation replaced is left as it is)
                path.write_bytes(mutate(path.read_bytes(), mutation))
        assume(within_limits(folder))
        start = time.perf_counter()
        run_both(folder, dynamic_input, static_input, edits)
        OUTCOMES['cases'] += 1
        OUTCOMES['seconds'] += time.perf_counter() - start
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ---------------------------------------------------------------------- earlier findings in the static script, now fixed
def test_known_static_writes_before_validation(earlier_run, tmp_path):
    folder = tmp_path / 'case'
    shutil.copytree(earlier_run, folder)
    (folder / 'inputfile.dat').write_text((folder / 'inputfile.dat').read_text() + '# a changed input\n')
    (folder / 'Structures' / 'force.dat').write_text('0 0 -1 0 0 0\n')  # one line for three bodies
    check_run('static', folder, 'inputfile.dat')


def test_known_static_singular_far_body(earlier_run, tmp_path):
    folder = tmp_path / 'case'
    shutil.copytree(earlier_run, folder)
    clones = folder / 'Structures' / 'shell_N_12_Rg_1.clones'
    clones.write_text(clones.read_text().replace('0 5 5 1 0 0 0', '0 5 1e20 1 0 0 0'))
    check_run('static', folder, 'inputfile.dat')


def test_known_static_output_folder_is_a_file(earlier_run, tmp_path):
    folder = tmp_path / 'case'
    shutil.copytree(earlier_run, folder)
    edit_input(folder / 'inputfile.dat', output_name='Structures/force.dat/run')
    check_run('static', folder, 'inputfile.dat')


# ---------------------------------------------------------------------- forged restart records (issue 27)
# A record rewritten with its checksum recomputed: any field replaced by a value of another type, sign or size.
# The restart must end in one line (exit 2) or run (exit 0); never a traceback, never a memory or time bomb.
FORGED_VALUES = [-1, 0, 7, 2 ** 40, 2 ** 70, -2 ** 63, 1.5, float('nan'), float('inf'), 'x', '', '../../x', None,
                 True, [], {}, [1, 2], {'a': 1}, [[[[[[[[1]]]]]]]], 'e' * 64]


def _record_paths(value, path=()):
    """Every (path of keys) inside a decoded record, containers and leaves."""
    import numpy as np
    found = [path] if path else []
    if isinstance(value, dict):
        for key, item in value.items():
            found += _record_paths(item, path + (key,))
    elif isinstance(value, list):  # a tuple is replaced whole (its items cannot be assigned)
        for index, item in enumerate(value):
            found += _record_paths(item, path + (index,))
    return found


# Every field a record of this package may hold (issue 48: the fuzzer forged only the fields its scenes' records
# have; the others, absent there, are added with a forged value).  '*' stands for each structure ID of the scene.
KNOWN_FIELDS = (
    ('step',), ('run_id',), ('config_offsets',), ('config_offsets', '*'), ('config_ends',), ('config_ends', '*'),
    ('snapshots',), ('snapshots', '*'), ('fingerprint',), ('stop',), ('stop_files',), ('stop_files', '*'),
    ('side_files',), ('side_files', 'concentration'), ('state',), ('state', 'locations'), ('state', 'orientations'),
    ('state', 'rng'), ('state', 'rng', 'bit_generator'), ('state', 'rng', 'state'), ('state', 'rng', 'state', 'key'),
    ('state', 'rng', 'state', 'pos'), ('state', 'rng', 'has_gauss'), ('state', 'rng', 'gauss'),
    ('state', 'counters'), ('state', 'scheme'), ('state', 'sampler'),
    ('state', 'sampler', 'locations'), ('state', 'sampler', 'orientations'), ('state', 'sampler', 'max_translation'),
    ('state', 'sampler', 'max_angle_shift'), ('state', 'sampler', 'counters')) + tuple(
    ('state', 'scheme', name) for name in (
        'first_guess', 'earlier_guesses', 'roller_torque_guess', 'previous_velocities', 'concentration_guess',
        'invalid_configurations', 'preconditioner_step', 'preconditioner_configuration', 'preconditioner_solves',
        'preconditioner_fewest', 'preconditioner_lifetime', 'concentration_preconditioner_configuration',
        'concentration_preconditioner_solves', 'concentration_preconditioner_fewest'))


def _all_record_paths(record, structure_ids):
    """The paths of ``record`` (``_record_paths``) and of every known field it lacks (its parents created when
    forged)."""
    paths = _record_paths(record)
    known = set(map(tuple, paths))
    for field in KNOWN_FIELDS:
        for name in (structure_ids if '*' in field else [None]):
            path = tuple(name if key == '*' else key for key in field)
            if path not in known:
                known.add(path)
                paths.append(path)
    return paths


def _forged_value(draw_index, old):
    import numpy as np
    extra = [np.zeros((2, 3)), np.full(5, np.nan), np.zeros(0), np.arange(3), np.zeros((2, 4)), np.zeros((3, 6)),
             np.ones((2, 6)), np.ones(6), np.ones(27), np.ones((1, 6)), np.ones((2, 1)), np.ones((1, 27)),
             (np.zeros((2, 3)), np.zeros((2, 4))), (np.ones((2, 3)), np.full((2, 4), 0.5)),
             np.eye(1, 624, 0, np.uint32)[0], np.full(624, 7, np.uint32), [0, 2 ** 40], [5, 3], [0, 0]]
    values = FORGED_VALUES + extra + ([old[:1], old * 2, old.reshape(-1), old[..., :1]]
                                      if isinstance(old, np.ndarray) and old.size else [])
    return values[draw_index % len(values)]


def _run_scene(kind, folder):
    """(status, out, err) of the scene's script run in-process on ``folder/input.dat``."""
    if kind != 'mcmc':
        return run_in_process('dynamic', folder, 'input.dat')
    import contextlib
    import importlib
    import io
    import utils
    main = importlib.import_module('many_bodyMCMC.many_body_MCMC').main
    out, err, previous = io.StringIO(), io.StringIO(), os.getcwd()
    os.chdir(str(folder))
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = utils.fail_cleanly(main, ['input.dat'])
            except SystemExit as stop:
                status = stop.code
    finally:
        os.chdir(previous)
    return (0 if status is None else status), out.getvalue(), err.getvalue()


RECORD_SCENES = ('driven', 'one_file', 'articulated', 'mcmc', 'adams_bashforth', 'phoretic', 'rollers')


@pytest.fixture(scope='module')
def recorded_runs(tmp_path_factory):
    """{scene: (folder, restart step)}: finished runs whose record of the restart step the fuzzer forges."""
    from safety_scenes import mcmc_scene
    from safety_scenes import articulated_scene, driven_scene
    root = tmp_path_factory.mktemp('records')
    from safety_scenes import dynamic_scene, phoretic_scene
    scenes = {'driven': (driven_scene(root / 'driven', n_steps=6), 3),
              'one_file': (driven_scene(root / 'one_file', n_steps=6, save_clones='one_file'), 3),
              'articulated': (articulated_scene(root / 'articulated', n_steps=6), 3),
              'mcmc': (mcmc_scene(root / 'mcmc', n_steps=80, n_save=40), 40),
              # issue 48: Adams-Bashforth (previous_velocities), a phoretic run (the concentration fields and
              # side_files), rollers (the roller torque guess)
              'adams_bashforth': (dynamic_scene(root / 'adams_bashforth', n_steps=6, n_save=3), 3),
              'phoretic': (phoretic_scene(root / 'phoretic', n_steps=6, n_save=3), 3),
              'rollers': (dynamic_scene(root / 'rollers', n_steps=6, n_save=3,
                                        scheme='stochastic_adams_bashforth_rollers'), 3)}
    for kind, (folder, _) in scenes.items():
        assert _run_scene(kind, folder)[0] == 0, kind
    return scenes


@settings(max_examples=max(20, EXAMPLES // 3), derandomize=not RANDOM, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(scene=st.sampled_from(RECORD_SCENES), where=st.integers(0, 10 ** 6), what=st.integers(0, 10 ** 6))
def test_forged_restart_records_never_make_a_traceback(recorded_runs, tmp_path_factory, scene, where, what):
    """Issue 27: any field of a restart record (dynamic, save_clones one_file, articulated, Monte Carlo) replaced
    with a value of another type, sign or size, the checksum recomputed: one-line refusal or a run, never a
    traceback.  (A value of the right kind cannot be told from the original: the checksum guards damage only.)"""
    from safety_scenes import forge_record, set_options_text
    from multi_bodies.run.restart_records import restart_record
    base, step = recorded_runs[scene]
    folder = tmp_path_factory.mktemp('forged')
    shutil.rmtree(folder)
    shutil.copytree(base, folder)
    record = restart_record(str(folder / 'data' / 'run'), step)
    paths = _all_record_paths(record, sorted(record.get('snapshots') or {}))
    path = paths[where % len(paths)]

    def change(record):
        target = record
        for key in path[:-1]:
            if isinstance(target, dict) and not isinstance(target.get(key), (dict, list)):
                target[key] = {}  # a field the record lacks: its parents made
            target = target[key]
        old = target[path[-1]] if isinstance(target, list) or path[-1] in target else None
        target[path[-1]] = _forged_value(what, old)
    try:
        forge_record(str(folder / 'data' / 'run'), step, change)
        (folder / 'input.dat').write_text(set_options_text(folder, initial_step=step))
        try:
            try:
                status, out, err = _run_scene(scene, folder)
            except Exception as error:
                raise Finding('forged %s: %s' % ('.'.join(str(k) for k in path[:2]),
                                                 traceback_signature(scene, error)),
                              'record field %r forged: %s' % (path, ''.join(traceback.format_exception(error))[-2000:]))
            OUTCOMES['forged records, exit %s' % status] += 1
            if status not in (0, 2) or 'Traceback' in out + err:
                raise Finding('forged %s: exit %s%s' % ('.'.join(str(k) for k in path[:2]), status,
                                                        ', traceback' if 'Traceback' in out + err else ''),
                              '%r: %s' % (path, err[-2000:]))
            if status == 2 and len([line for line in err.splitlines() if line.startswith('error:')]) != 1:
                raise Finding('forged %s: not one error line' % '.'.join(str(k) for k in path[:2]), err[-2000:])
        except Finding as finding:
            FINDINGS[finding.signature].append('%s, record field %r forged\n%s' % (scene, path, finding))
            if not COLLECT:
                raise
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ---------------------------------------------------------------------- the report (last: after both fuzzers)
def test_report_fuzz_outcomes():
    """Prints how many cases ran and how each script ended (run with -s to see it)."""
    if not OUTCOMES:
        pytest.skip('the fuzz tests did not run in this session')
    print('\nfuzz cases: %d (%.1f s in the scripts); outcomes: %s'
          % (OUTCOMES['cases'], OUTCOMES['seconds'],
             ', '.join('%s: %d' % (k, v) for k, v in sorted(OUTCOMES.items()) if k not in ('cases', 'seconds'))))
    for signature, examples in sorted(FINDINGS.items()):
        print('finding (%d cases): %s\n    first: %s\n    %s' % (len(examples), signature, examples[0].splitlines()[0],
                                                            examples[0].splitlines()[-1][:300]))
    if COLLECT:
        print('%d kinds of status-2 message, most frequent first:' % len(MESSAGES))
        for text, count in MESSAGES.most_common():
            print('%5d  %s' % (count, text))
    assert OUTCOMES['cases'] > 0 or any(k.startswith('forged') for k in OUTCOMES)
    if OUTCOMES['cases'] >= 100:  # about one case in four is classified: both kinds were checked
        assert OUTCOMES['classified refused, exit 2 as expected'] > 0
        assert OUTCOMES['classified harmless, exit 0 as expected'] > 0
