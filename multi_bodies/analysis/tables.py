"""Text tables and charts of the analyses (names and columns in doc/analysis.md).

Every table starts with ``#`` lines that say what was analysed (frames,
particles, blocks, box) and name the columns; numbers are written with
``repr``-like precision (``%.10g``).  Tables are written to ``path + '.part'``
first and then renamed, so a reader never sees half a table (the run-time
sampler rewrites its table at every save).  Charts need matplotlib, imported
only when a chart is drawn; without it :func:`draw_chart` returns a message
and the tables are still written.
"""
import os

import numpy as np


def write_table(path, header_lines, column_names, columns):
    """Write columns (list of (n,) arrays) under ``# header`` lines and a ``# name1 name2 ...`` line."""
    data = np.column_stack([np.asarray(c, dtype=float) for c in columns]) if columns else np.zeros((0, 0))
    lines = ['# %s' % line for line in header_lines]
    lines.append('# ' + ' '.join(column_names))
    lines.extend(' '.join('%.10g' % v for v in row) for row in data)
    part = path + '.part'
    with open(part, 'w') as f:
        f.write('\n'.join(lines) + '\n')
    os.replace(part, path)
    return path


def _describe(result, extra=()):
    return ['frames %d, particles %d, blocks %d (error: standard error of the block means)'
            % (result.get('frames', -1), result['particles'], result['blocks'])] + list(extra)


def write_pair_correlation(path, result, box):
    header = _describe(result, ['g(r), %d-d%s, periodic_length %s; normalisation: %s'
                                % (result['dimension'], ' (in the plane x, y)' if result['dimension'] == 2 else '',
                                   ' '.join('%g' % v for v in box), result['normalisation'])])
    return write_table(path, header, ['r', 'g', 'g_error'], [result['r'], result['g'], result['g_error']])


def write_structure_factor(path, radial_path, result):
    """The S(k) table of every half-space wavevector and the radially binned table."""
    d = result['dimension']
    names = ['n_x', 'n_y', 'n_z'][:d] + ['k_x', 'k_y', 'k_z'][:d] + ['k']
    columns = [result['indices'][:, a] for a in range(d)] + [result['wavevectors'][:, a] for a in range(d)]
    columns.append(result['k'])
    for row, (a, b) in enumerate(result['pairs']):
        label = 'S' if (a, b) == ('all', 'all') else 'S_%s_%s' % (a, b)
        names += [label, label + '_error']
        columns += [result['S'][row], result['S_error'][row]]
    header = _describe(result, ['S(k) = Re<rho_a(k) rho_b(k)^*>/sqrt(N_a N_b), %d-d, box %s, k = 2 pi n / L'
                                % (d, ' '.join('%g' % v for v in result['box']))])
    write_table(path, header, names, columns)
    radial = result['radial']
    names, columns = ['k', 'wavevectors'], [radial['k'], radial['count']]
    for row, (a, b) in enumerate(result['pairs']):
        label = 'S' if (a, b) == ('all', 'all') else 'S_%s_%s' % (a, b)
        names += [label, label + '_error']
        columns += [radial['S'][row], radial['S_error'][row]]
    write_table(radial_path, header + ['radially binned: mean over the wavevectors of each bin of |k|'], names,
                columns)
    return path, radial_path


def write_msd(path, result):
    header = _describe(result, ['mean-square displacements (lengths squared) against the lag time; a time origin '
                                'every %d frames' % result['origin_every']])
    return write_table(path, header, ['lag', 'time', 'msd_xy', 'msd_xy_error', 'msd_z', 'msd_z_error'],
                       [result['lag'], result['time'], result['msd_xy'], result['msd_xy_error'], result['msd_z'],
                        result['msd_z_error']])


def write_fkt(path, result, shell_k, shell_labels=None):
    """F(k,t) table: lag, time, then per shell Fs, its error (and F, its error); shell_labels name the shells."""
    names, columns = ['lag', 'time'], [result['lag'], result['time']]
    for shell, k in enumerate(shell_k):
        names += ['Fs_k%d' % shell, 'Fs_k%d_error' % shell]
        columns += [result['Fs'][:, shell], result['Fs_error'][:, shell]]
        if 'F' in result:
            names += ['F_k%d' % shell, 'F_k%d_error' % shell]
            columns += [result['F'][:, shell], result['F_error'][:, shell]]
    header = _describe(result, ['F(k,t): Fs = self part, F = collective (F(k,0) = S(k)); a time origin every %d '
                                'frames; shells: %s' % (result['origin_every'], ', '.join(
                                    'k%d = %.8g%s' % (i, k, ' (%s)' % shell_labels[i] if shell_labels else '')
                                    for i, k in enumerate(shell_k)))])
    return write_table(path, header, names, columns)


def draw_chart(path, title, x_label, y_label, curves, log_x=False, reference=None):
    """A PNG chart of curves [(label, x, y, error)], with an optional reference curve (label, x, y).

    Returns None when written, else the reason (matplotlib missing), for the log.
    """
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        return 'matplotlib is not installed: chart %s skipped (pip install matplotlib)' % path
    figure = build_chart(title, x_label, y_label, curves, log_x=log_x, reference=reference)
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return None


def build_chart(title, x_label, y_label, curves, log_x=False, reference=None):
    """The matplotlib figure of :func:`draw_chart` (matplotlib imported by the caller), tick labels that would
    overlap hidden (:func:`hide_overlapping_tick_labels`)."""
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(figsize=(6, 4))
    for label, x, y, error in curves:
        if error is not None and np.any(np.isfinite(error)):
            axes.errorbar(x, y, yerr=np.nan_to_num(error), fmt='.-', ms=3, capsize=1.5, lw=0.8, label=label)
        else:
            axes.plot(x, y, '.-', ms=3, lw=0.8, label=label)
    if reference is not None:
        axes.plot(reference[1], reference[2], 'k--', lw=0.8, label=reference[0])
    if log_x:
        axes.set_xscale('log')
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_label)
    axes.set_title(title)
    axes.legend(fontsize=8)
    figure.tight_layout()
    hide_overlapping_tick_labels(figure, axes)
    return figure


def hide_overlapping_tick_labels(figure, axes, gap=3.0):
    """Hide the tick labels that would overlap one another (a log axis over less than a decade labels its minor
    ticks too: 2x10^-2, 3x10^-2, ... ran into each other): the major labels first, then the minor ones that fit,
    each kept only if its box stays ``gap`` pixels clear of every label kept before."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    for axis in (axes.xaxis, axes.yaxis):
        kept = []
        for which in ('major', 'minor'):
            for label in axis.get_ticklabels(which=which):
                if not label.get_visible() or not label.get_text():
                    continue
                box = label.get_window_extent(renderer).expanded(1.0, 1.0)
                box = box.from_extents(box.x0 - gap, box.y0 - gap, box.x1 + gap, box.y1 + gap)
                if any(box.overlaps(other) for other in kept):
                    label.set_visible(False)
                else:
                    kept.append(box)
