"""The scheme registry: every scheme of the scripts, its kind and what it needs, declared once (floor 3).

The option parser (``input_options``: the names the ``scheme`` option accepts, which options a scheme uses),
the schemes' implementations (``quaternion_integrator.schemes`` keys its classes by these names and refuses a
class without an entry or an entry without a class), the model's set-up (rollers, the slip-length and obstacle
refusals), the advisor (the dense and roller counterparts of a scheme) and the manual (``doc/options.md``,
``doc/dynamics.md``: ``tests/test_scheme_table.py`` checks their lists against this one) read the schemes here;
nothing recognises a scheme by the pattern of its name.

Each :data:`SchemeEntry` holds

* ``name``: the manual's name;
* ``kind``: ``'static'`` (``multi_bodies_utilities.py``), ``'deterministic'`` or ``'stochastic'``
  (``multi_bodies.py``; stochastic: the scheme draws noise and reads kT, rf_delta, update_PC);
* ``algebra``: ``'iterative'`` (GMRES and Lanczos, matrix-free) or ``'dense'`` (the full blob matrix: O(N^3) a
  step, the dense memory check of a run applies);
* ``rollers``: single-blob rollers whose positions alone move (velocities (N, 3));
* ``articulated``: solves with joint constraints (``articulated`` lines);
* ``lubrication``: spheres with the near-field corrections of ``lubrication/``;
* ``obstacles``: solves the mixed problem of bodies of prescribed motion (obstacles, velocity files);
* ``slip_length``: takes slip-length bodies (``.slip_length`` files);
* ``dense_of``: for a dense scheme, the iterative scheme it stands in for (``*_DLA`` and
  ``deterministic_forward_euler_dense_algebra`` share its step, with dense products); else None;
* ``rollers_of``: for a roller scheme, the rigid-body scheme it stands in for (the advisor's single-blob model);
  else None.
"""
from collections import OrderedDict, namedtuple

SchemeEntry = namedtuple('SchemeEntry', ['name', 'kind', 'algebra', 'rollers', 'articulated', 'lubrication',
                                         'obstacles', 'slip_length', 'dense_of', 'rollers_of'])


def _entry(name, kind, algebra='iterative', rollers=False, articulated=False, lubrication=False, obstacles=False,
           slip_length=False, dense_of=None, rollers_of=None):
    return SchemeEntry(name, kind, algebra, rollers, articulated, lubrication, obstacles, slip_length, dense_of,
                       rollers_of)


# In the manual's order (doc/dynamics.md): static, deterministic, stochastic (rigid, dense, rollers, lubrication),
# articulated.
SCHEME_TABLE = OrderedDict((entry.name, entry) for entry in (
    _entry('body_mobility', 'static', 'dense', obstacles=True),
    _entry('mobility', 'static', obstacles=True, slip_length=True),
    _entry('resistance', 'static', 'dense', obstacles=True),
    _entry('deterministic_forward_euler', 'deterministic', obstacles=True, slip_length=True),
    _entry('deterministic_forward_euler_dense_algebra', 'deterministic', 'dense', obstacles=True,
           dense_of='deterministic_forward_euler'),
    _entry('deterministic_adams_bashforth', 'deterministic', obstacles=True, slip_length=True),
    _entry('deterministic_forward_euler_rollers', 'deterministic', rollers=True,
           rollers_of='deterministic_forward_euler'),
    _entry('deterministic_adams_bashforth_rollers', 'deterministic', rollers=True,
           rollers_of='deterministic_adams_bashforth'),
    _entry('deterministic_midpoint', 'deterministic', slip_length=True),
    _entry('stochastic_first_order_RFD', 'stochastic'),
    _entry('stochastic_adams_bashforth', 'stochastic'),
    _entry('stochastic_first_order_RFD_dense_algebra', 'stochastic', 'dense', dense_of='stochastic_first_order_RFD'),
    _entry('stochastic_traction_EM', 'stochastic'),
    _entry('Fixman', 'stochastic', 'dense'),
    _entry('stochastic_Slip_Trapz', 'stochastic', obstacles=True),
    _entry('stochastic_traction_AB', 'stochastic'),
    _entry('stochastic_Slip_Mid', 'stochastic', obstacles=True),
    _entry('stochastic_Slip_Mid_DLA', 'stochastic', 'dense', dense_of='stochastic_Slip_Mid'),
    _entry('stochastic_first_order_rollers', 'stochastic', rollers=True, rollers_of='stochastic_first_order_RFD'),
    _entry('stochastic_adams_bashforth_rollers', 'stochastic', rollers=True, rollers_of='stochastic_adams_bashforth'),
    _entry('stochastic_mid_point_rollers', 'stochastic', rollers=True),
    _entry('stochastic_trapezoidal_rollers', 'stochastic', rollers=True),
    _entry('stochastic_EM', 'stochastic'),
    _entry('stochastic_GDC_RFD', 'stochastic'),
    _entry('lubrication_trapezoidal', 'stochastic', lubrication=True),
    _entry('lubrication_EM', 'stochastic', lubrication=True),
    _entry('lubrication_trapezoidal_rollers', 'stochastic', rollers=True, lubrication=True),
    _entry('articulated_deterministic_forward_euler', 'deterministic', articulated=True),
    _entry('articulated_deterministic_midpoint', 'deterministic', articulated=True),
    _entry('articulated_deterministic_forward_euler_rollers', 'deterministic', rollers=True, articulated=True),
))


def scheme_names(**needs):
    """The names of the schemes whose entries have every field of ``needs`` (field name -> value), in the
    registry's order; ``dynamic=True`` selects the schemes of ``multi_bodies.py`` (deterministic and stochastic)."""
    dynamic = needs.pop('dynamic', None)
    unknown = set(needs) - set(SchemeEntry._fields)
    if unknown:
        raise KeyError('no scheme field %s' % ', '.join(sorted(unknown)))
    return tuple(name for name, entry in SCHEME_TABLE.items()
                 if all(getattr(entry, field) == value for field, value in needs.items())
                 and (dynamic is None or (entry.kind != 'static') == dynamic))


def scheme_entry(name):
    """The :data:`SchemeEntry` of scheme ``name``, or None for a name that is not a scheme of the registry."""
    return SCHEME_TABLE.get(name)


def moves_rollers(name):
    """True when scheme ``name`` moves single-blob rollers (False for a name that is not a scheme)."""
    entry = SCHEME_TABLE.get(name)
    return entry is not None and entry.rollers


def dense_variants():
    """Iterative scheme -> the dense scheme that stands in for it (``dense_of``)."""
    return {entry.dense_of: name for name, entry in SCHEME_TABLE.items() if entry.dense_of is not None}


def roller_variants():
    """Rigid-body scheme -> the roller scheme that stands in for it (``rollers_of``)."""
    return {entry.rollers_of: name for name, entry in SCHEME_TABLE.items() if entry.rollers_of is not None}


def scheme_has(name, field):
    """The registry's ``field`` of scheme ``name`` (``'lubrication'``, ``'articulated'``, ...; False for a name
    that is not a scheme)."""
    entry = SCHEME_TABLE.get(name)
    return False if entry is None else getattr(entry, field)
