"""Set-up shared by the two scripts: bodies from the ``structure`` lines, and ``.bodies_info``.

Library floor (ARCHITECTURE.md floor 3): the scripts call these; nothing
here writes simulation output other than the file it is asked to write.
"""
import os

import numpy as np

import utils
from body.body import Body
from multi_bodies.run_output import (RESTART_SUFFIX, clones_name, config_name, read_config_snapshot,  # noqa: F401
                                     write_bodies_info)
from multi_bodies.structure_files import read_clones_file, read_slip_file, read_vertex_file


def read_bodies(options, set_slip_by_ID, single_blob_bodies=False, restart_record=None):
    """Bodies of every ``structure`` line (restart snapshots when ``initial_step > 0``).

    Parameters
    ----------
    options : the validated input options
    set_slip_by_ID : callable ``(body, slip (n, 3) or None)``, the slip hook
    single_blob_bodies : bool
        Refuse structures of more than one blob (roller schemes).
    restart_record : dict or None
        With ``save_clones one_file`` and ``initial_step > 0``, the record of
        ``output_name.restart`` at that step: it says where the snapshot
        starts in each ``.config`` file.

    Returns (list of Body, list of (ID, number of bodies) per structure type).
    """
    if not options.structures:
        raise utils.UserInputError("%s: no 'structure' line; add 'structure <file.vertex> <file.clones>'"
                                   % options.input_file)
    bodies, types = [], []
    for spec in options.structures:
        clones = spec.clones_file
        snapshot = None
        restart_step = getattr(options, 'initial_step', 0)
        if restart_step > 0 and getattr(options, 'save_clones', 'one_file_per_step') == 'one_file':
            clones = config_name(options.output_name, spec.ID)
            offsets = (restart_record or {}).get('config_offsets') or {}
            if spec.ID not in offsets or not os.path.isfile(clones):
                raise utils.UserInputError(
                    '%s: initial_step %d restarts a save_clones one_file run, but %s%s has no record of step %d '
                    'for %s; restart from a saved step' % (options.where('initial_step'), restart_step,
                                                          options.output_name, RESTART_SUFFIX, restart_step, clones))
            snapshot = read_config_snapshot(clones, offsets[spec.ID])
        elif restart_step > 0:
            clones = clones_name(options.output_name, spec.ID, options.initial_step)
            if not os.path.isfile(clones):
                raise utils.UserInputError(
                    '%s: initial_step %d restarts from %s, which does not exist; restart from a saved step '
                    '(save_clones one_file_per_step writes one file per saved step)'
                    % (options.where('initial_step'), options.initial_step, clones))
        reference = read_vertex_file(spec.vertex_file, spec.where)
        if snapshot is None:
            locations, orientations = read_clones_file(clones, spec.where)
        else:
            locations, orientations = snapshot
            orientations = orientations / np.linalg.norm(orientations, axis=1)[:, None]
        slip = None
        if spec.slip_file is not None:
            slip = read_slip_file(spec.slip_file, spec.where)
            if slip.shape[0] != reference.shape[0]:
                raise utils.UserInputError('%s: slip file %s has %d blobs but vertex file %s has %d'
                                           % (spec.where, spec.slip_file, slip.shape[0], spec.vertex_file,
                                              reference.shape[0]))
        if single_blob_bodies and reference.shape[0] != 1:
            raise utils.UserInputError('%s: roller schemes need single-blob bodies, but %s has %d blobs'
                                       % (spec.where, spec.vertex_file, reference.shape[0]))
        print('Creating structures = %s' % clones)
        body_length = None
        for location, orientation in zip(locations, orientations):
            body = Body(location, orientation, reference, options.blob_radius)
            body.ID = spec.ID
            set_slip_by_ID(body, slip)
            if body_length is None:
                body_length = body.calc_body_length()
            body.body_length = body_length
            bodies.append(body)
        types.append((spec.ID, locations.shape[0]))
    return bodies, types
