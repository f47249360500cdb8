"""Set-up shared by the two scripts: bodies from the ``structure`` lines, and ``.bodies_info``.

Library floor (ARCHITECTURE.md floor 3): the scripts call these; nothing
here writes simulation output other than the file it is asked to write.
"""
import os

import utils
from body.body import Body
from multi_bodies.structure_files import read_clones_file, read_slip_file, read_vertex_file


def clones_name(output_name, structure_id, step):
    """Name of a saved snapshot: ``output_name.ID.<step, 8 digits>.clones`` (SPEC §2.1)."""
    return '%s.%s.%s.clones' % (output_name, structure_id, str(step).zfill(8))


def read_bodies(options, set_slip_by_ID, single_blob_bodies=False):
    """Bodies of every ``structure`` line (restart snapshots when ``initial_step > 0``).

    Parameters
    ----------
    options : the validated input options
    set_slip_by_ID : callable ``(body, slip (n, 3) or None)``, the slip hook
    single_blob_bodies : bool
        Refuse structures of more than one blob (roller schemes).

    Returns (list of Body, list of (ID, number of bodies) per structure type).
    """
    if not options.structures:
        raise utils.UserInputError("%s: no 'structure' line; add 'structure <file.vertex> <file.clones>'"
                                   % options.input_file)
    bodies, types = [], []
    for spec in options.structures:
        clones = spec.clones_file
        if getattr(options, 'initial_step', 0) > 0:
            clones = clones_name(options.output_name, spec.ID, options.initial_step)
            if not os.path.isfile(clones):
                raise utils.UserInputError(
                    '%s: initial_step %d restarts from %s, which does not exist; restart from a saved step '
                    '(save_clones one_file_per_step writes one file per saved step)'
                    % (options.where('initial_step'), options.initial_step, clones))
        reference = read_vertex_file(spec.vertex_file, spec.where)
        locations, orientations = read_clones_file(clones, spec.where)
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


def write_bodies_info(path, types, num_blobs):
    """``.bodies_info``: number of body types, their names, bodies per type, bodies, blobs."""
    with open(path, 'w') as f:
        f.write('num_of_body_types  %d\n' % len(types))
        f.write('body_names         %s\n' % str([name for name, _ in types]))
        f.write('body_types         %s\n' % str([count for _, count in types]))
        f.write('num_bodies         %d\n' % sum(count for _, count in types))
        f.write('num_blobs          %d\n' % num_blobs)
