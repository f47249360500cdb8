"""The public names of the blob products, made once for every backend.

Each backend supplies one factory ``make_product(kind, wall)`` returning
``f(r_vectors (N, 3), vector (3N,), eta, a, periodic_length=(0, 0, 0)) -> (3N,)``
and one ``source_target(source, target, force, radius_source, radius_target,
eta, periodic_length, wall)``; this module turns them into the named
functions ``single_wall_mobility_trans_times_force``, ... that the registry
looks up.
"""
PRODUCT_KINDS = ('trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque')
DOMAINS = (('single_wall', True), ('no_wall', False))
_DESCRIPTIONS = {'trans_times_force': 'blob velocities from blob forces',
                 'trans_times_torque': 'blob velocities from blob torques',
                 'rot_times_force': 'blob angular velocities from blob forces',
                 'rot_times_torque': 'blob angular velocities from blob torques'}


def product_functions(make_product, backend_label):
    """Dict of the eight named products ``{domain}_mobility_{kind}`` built by ``make_product``."""
    functions = {}
    for domain, wall in DOMAINS:
        for kind in PRODUCT_KINDS:
            function = make_product(kind, wall)
            function.__name__ = '%s_mobility_%s' % (domain, kind)
            function.__doc__ = '%s: %s (%s); r_vectors (N, 3), vector (3N,) -> (3N,).' % (
                backend_label, _DESCRIPTIONS[kind], 'with the wall' if wall else 'free space')
            functions[function.__name__] = function
    return functions


def source_target_functions(source_target, backend_label):
    """Dict of ``single_wall_mobility_source_target`` and ``no_wall_mobility_source_target``."""
    functions = {}
    for domain, wall in DOMAINS:
        def function(source, target, force, radius_source, radius_target, eta, periodic_length=(0, 0, 0),
                     _wall=wall):
            return source_target(source, target, force, radius_source, radius_target, eta, periodic_length, _wall)
        function.__name__ = '%s_mobility_source_target' % domain
        function.__doc__ = ('%s: velocity (3Nt,) at targets (Nt, 3) of radius radius_target from forces (3Ns,) '
                            'on sources (Ns, 3) of radius radius_source (%s).'
                            % (backend_label, 'with the wall' if wall else 'free space'))
        functions[function.__name__] = function
    return functions
