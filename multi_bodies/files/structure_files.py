"""Readers and writers of the structure files and of per-body data files.

Formats (SPEC section 1.3); in every file ``#`` starts a comment and blank
lines are skipped.

* ``.vertex``: first line the number of blobs ``n`` (more numbers may follow
  on that line and are ignored); then ``n`` lines ``x y z`` or ``x y z a``:
  the blob positions in the body frame and, optionally, the radius of each
  blob (manual section 2; either every line has the fourth column or none).
  Without it every blob gets ``blob_radius`` of the input file.
* ``.clones``: first line the number of bodies; then one line per body
  ``x y z s p1 p2 p3`` (location and scalar-first quaternion, normalised
  when read).  Its reader and writer are in ``snapshots.py`` (with the
  saved snapshots of runs), built on ``_read_counted_table`` here.
* ``.slip``: first line the number of blobs; then ``n`` lines ``ux uy uz``,
  the active slip of each blob in the body frame.
* force file (scheme ``mobility``): one line per body ``Fx Fy Fz Tx Ty Tz``.
* velocity file (scheme ``resistance``, and the fourth file of a ``structure`` line): one line per body
  ``vx vy vz wx wy wz``.  Either may start with a line holding the number of bodies alone (the published
  ``rollers_pillars`` velocity file does).

Every reader raises ``utils.UserInputError`` naming the file and line and
what was expected when a file is missing, is not UTF-8 text or is
malformed.  Numbers must be finite and at most ``LARGEST_VALUE`` in
magnitude (squares of distances must not overflow): ``nan``, ``inf`` and
``1e400`` are refused when the file is read, not deep in a solver.  Extra
values on a ``.clones`` or ``.slip`` line are ignored with a warning; a
``.vertex`` line with more than four values, a fourth column on some lines
only, or a radius that is not positive is an error.
"""
import os

import numpy as np

from utils import UserInputError, read_text_file, warn_user

# Largest magnitude accepted in a structure or body file: its square (1e300) still fits in a double.
LARGEST_VALUE = 1e150


def _meaningful_lines(path, kind, referenced_from=None):
    """(line number, tokens) of the non-empty lines of ``path`` after removing comments."""
    origin = ' (named in %s)' % referenced_from if referenced_from else ''
    text = read_text_file(path, '%s file' % kind,
                          'check the path%s, which is relative to the directory the script runs in (%s)'
                          % (origin, os.getcwd()))
    rows = []
    for number, raw in enumerate(text.splitlines(), start=1):
        tokens = raw.split('#', 1)[0].split()
        if tokens:
            rows.append((number, tokens))
    return rows


def _parse_row(path, number, tokens, columns, expected):
    """First ``columns`` numbers of one line, or UserInputError (also for nan, inf, |x| > LARGEST_VALUE)."""
    if len(tokens) < columns:
        raise UserInputError("%s, line %d: expected %s (%d numbers), found %d value(s): '%s'"
                             % (path, number, expected, columns, len(tokens), ' '.join(tokens)))
    try:
        numbers = [float(t) for t in tokens[:columns]]
    except ValueError:
        raise UserInputError("%s, line %d: expected %s (%d numbers), cannot read '%s' as numbers"
                             % (path, number, expected, columns, ' '.join(tokens[:columns])))
    for token, value in zip(tokens, numbers):
        if not np.isfinite(value):
            raise UserInputError("%s, line %d: '%s' is not a finite number (expected %s); fix the value"
                                 % (path, number, token, expected))
        if abs(value) > LARGEST_VALUE:
            raise UserInputError("%s, line %d: '%s' is too large (magnitude above %g, whose square overflows); "
                                 "rescale the units" % (path, number, token, LARGEST_VALUE))
    return numbers


def _check_extra_columns(path, data, columns, expected, kind):
    """Warn once per file about lines with more than ``columns`` values (the extra ones are ignored)."""
    longer = [(n, t) for n, t in data if len(t) > columns]
    if longer:
        number, tokens = longer[0]
        warn_user("%s, line %d: %d values, but a %s line holds %d (%s); the extra values are ignored "
                  "(%d line(s) affected)" % (path, number, len(tokens), kind, columns, expected, len(longer)))


def _read_counted_table(path, kind, columns, expected, referenced_from, exact_count):
    """Read a file whose first line is a count followed by rows of ``columns`` numbers.

    Returns an array of shape (count, columns).  ``exact_count``: more rows
    than announced is an error (otherwise the extra rows are ignored, as the
    published reader of ``.clones`` files does).
    """
    rows = _meaningful_lines(path, kind, referenced_from)
    if not rows:
        raise UserInputError("%s file '%s' is empty: its first line must hold the number of %s"
                             % (kind, path, 'rows'))
    number, tokens = rows[0]
    try:
        count = int(tokens[0])
    except ValueError:
        raise UserInputError("%s, line %d: the first line of a %s file must start with an integer count, "
                             "found '%s'" % (path, number, kind, tokens[0]))
    if count < 1:
        raise UserInputError("%s, line %d: the count must be a positive integer, found %d" % (path, number, count))
    data = rows[1:]
    if len(data) < count:
        raise UserInputError("%s: the first line announces %d %s but the file has only %d"
                             % (path, count, expected + ' line(s)', len(data)))
    if exact_count and len(data) > count:
        raise UserInputError("%s, line %d: the first line announces %d %s but the file has %d; "
                             "fix the count" % (path, data[count][0], count, expected + ' line(s)', len(data)))
    if kind == 'vertex':
        for n, t in data:
            if len(t) > columns:
                raise UserInputError(
                    "%s, line %d: %d values, but a vertex line holds x y z or x y z radius; remove the extra "
                    "value(s)" % (path, n, len(t)))
    else:
        _check_extra_columns(path, data, columns, expected, kind)
    table = [_parse_row(path, n, t, columns, expected) for n, t in data[:count]]
    # Rows past the count are still checked so that a typo there is reported.
    for n, t in data[count:]:
        _parse_row(path, n, t, columns, expected)
    return np.array(table, dtype=float).reshape(count, columns)


def read_vertex_file(path, referenced_from=None, return_radii=False):
    """Blob positions of the reference configuration, shape (n, 3).

    ``return_radii``: return ``(positions (n, 3), radii (n,) or None)``, the
    radii of the optional fourth column (None when the file has three
    columns).  Without it, a file that gives radii is refused unless the
    caller asked for them (so a radius is never dropped silently).  Two
    blobs at the same position are refused: they make the body's blob
    mobility singular.
    """
    rows = _meaningful_lines(path, 'vertex', referenced_from)
    four = [len(t) >= 4 for _, t in rows[1:]]
    with_radii = bool(four) and any(four)
    if with_radii and not all(four[:max(1, len(four))]):
        first = next(n for (n, t), has in zip(rows[1:], four) if not has)
        some = next(n for (n, t), has in zip(rows[1:], four) if has)
        raise UserInputError("%s, line %d: a blob radius in a fourth column, but line %d has none; give every blob "
                             "its radius or none (then all get blob_radius)" % (path, some, first))
    columns = 4 if with_radii else 3
    table = _read_counted_table(path, 'vertex', columns, 'blob position x y z' + (' and radius' if with_radii
                                                                                 else ''),
                                referenced_from, exact_count=True)
    blobs, radii = table[:, :3].copy(), (table[:, 3].copy() if with_radii else None)
    if radii is not None and np.any(radii <= 0):
        bad = int(np.argmax(radii <= 0))
        raise UserInputError("%s, line %d: blob radius %r in the fourth column; a radius must be positive"
                             % (path, rows[1 + bad][0], float(radii[bad])))
    from multi_bodies.files.input_options import SCALE_RANGE  # the range of the blob_radius option
    if radii is not None and np.any((radii < SCALE_RANGE[0]) | (radii > SCALE_RANGE[1])):
        bad = int(np.argmax((radii < SCALE_RANGE[0]) | (radii > SCALE_RANGE[1])))
        raise UserInputError("%s, line %d: blob radius %r in the fourth column; a radius must lie between %g and %g, "
                             "as blob_radius (beyond that eta a^3 over- or underflows in double precision); rescale "
                             "the units" % ((path, rows[1 + bad][0], float(radii[bad])) + SCALE_RANGE))
    if radii is not None and not return_radii:
        raise UserInputError("%s: the vertex file gives a radius per blob (fourth column), which this program "
                             "does not use; remove the fourth column" % path)
    _, first, counts = np.unique(blobs, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        repeated = blobs[first[np.argmax(counts > 1)]]
        same = np.flatnonzero(np.all(blobs == repeated, axis=1))
        lines = [n for n, t in rows[1:]]
        raise UserInputError("%s, lines %d and %d: two blobs at the same position %s make the mobility of the "
                             "body singular; remove one of the lines and fix the count"
                             % (path, lines[same[0]], lines[same[1]], ' '.join(repr(float(v)) for v in repeated)))
    return (blobs, radii) if return_radii else blobs


def read_slip_file(path, referenced_from=None):
    """Active slip of every blob in the body frame, shape (n, 3)."""
    return _read_counted_table(path, 'slip', 3, 'blob slip ux uy uz', referenced_from, exact_count=True)


def read_body_table(path, num_bodies, kind, referenced_from=None):
    """Force (or velocity) file: one line of six numbers per body, shape (Nb, 6).

    ``kind`` is 'force' or 'velocity' (it names what each line holds in messages).
    """
    expected = 'Fx Fy Fz Tx Ty Tz' if kind == 'force' else 'vx vy vz wx wy wz'
    rows = _meaningful_lines(path, kind, referenced_from)
    if rows and len(rows[0][1]) == 1 and rows[0][1][0] == str(num_bodies):
        rows = rows[1:]  # a leading count line, as in the published rollers_pillars velocity file
    table = []
    for number, tokens in rows:
        if len(tokens) != 6:
            raise UserInputError("%s, line %d: expected six numbers %s for one body, found %d value(s)"
                                 % (path, number, expected, len(tokens)))
        table.append(_parse_row(path, number, tokens, 6, expected))
    if len(table) != num_bodies:
        raise UserInputError("%s: expected one line per body (%d bodies in the structures), found %d lines"
                             % (path, num_bodies, len(table)))
    return np.array(table, dtype=float).reshape(num_bodies, 6)


def write_vertex_file(path, reference_configuration, comment=None, radii=None):
    """Write blob positions (shape (n, 3)) as a ``.vertex`` file with full precision.

    ``radii`` (n,): written as the fourth column (the radius of each blob).
    """
    blobs = np.asarray(reference_configuration, dtype=float).reshape(-1, 3)
    radii = None if radii is None else np.broadcast_to(np.asarray(radii, dtype=float), (blobs.shape[0],))
    with open(path, 'w') as f:
        if comment:
            for line in comment.splitlines():
                f.write('# %s\n' % line)
        f.write('%d\n' % blobs.shape[0])
        for k, (x, y, z) in enumerate(blobs):
            extra = '' if radii is None else ' %s' % repr(float(radii[k]))
            f.write('%s %s %s%s\n' % (repr(float(x)), repr(float(y)), repr(float(z)), extra))
