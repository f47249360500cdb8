"""The two random generators a run can draw from, behind one small interface (floor 2).

Every scheme and sampler draws only through ``standard_normal(n)`` (and the
Monte Carlo sampler through ``uniform(low, high, size)`` and ``random(size)``),
which both generators offer:

* ``default``: ``numpy.random.Generator`` (PCG64 from ``seed``), the
  package's generator;
* ``published``: :class:`PublishedGenerator`, numpy's legacy
  ``RandomState`` on MT19937, the generator of the published code.  Its
  normal numbers come from the polar Box-Muller method with one cached
  Gaussian, so the same MT19937 state gives other numbers than a
  ``Generator`` on it; a published ``.random_state`` (a pickled
  ``RandomState().get_state()``) repeats the published draws only with this
  generator.

``rng.bit_generator.state`` (read and set by the restart machinery) is, for
the published generator, the legacy state dict of numpy
(``RandomState.get_state(legacy=False)``: the MT19937 keys and position plus
``has_gauss`` and ``gauss``), so a restart repeats the uninterrupted run.
"""
import contextlib
import weakref

import numpy as np

GENERATORS = ('default', 'published')


class MT19937(np.random.MT19937):
    """The MT19937 of a :class:`PublishedGenerator`; its ``state`` includes the cached Gaussian.

    Named like numpy's class so that numpy's state dicts (``'bit_generator': 'MT19937'``) fit it unchanged.
    """

    _owner = None
    _setting = False

    def _legacy_owner(self):
        return self._owner() if self._owner is not None else None

    @property
    def state(self):
        owner = self._legacy_owner()
        if owner is None or self._setting:
            return np.random.MT19937.state.__get__(self)
        # RandomState.get_state reads the keys back through this getter, then adds the cached Gaussian
        self._setting = True
        try:
            return owner._legacy.get_state(legacy=False)
        finally:
            self._setting = False

    @state.setter
    def state(self, value):
        np.random.MT19937.state.__set__(self, {'bit_generator': value['bit_generator'], 'state': value['state']})
        owner = self._legacy_owner()
        if owner is not None and not self._setting:
            # RandomState.set_state sets the keys again (through this setter) and the cached Gaussian
            self._setting = True
            try:
                owner._legacy.set_state(dict(value, has_gauss=int(value.get('has_gauss', 0)),
                                             gauss=float(value.get('gauss', 0.0))))
            finally:
                self._setting = False


class PublishedGenerator:
    """numpy's legacy ``RandomState`` (MT19937), the generator of the published code, as the run's ``rng``.

    ``PublishedGenerator(seed)`` equals ``numpy.random.RandomState(seed)``;
    ``PublishedGenerator.from_legacy_state(state)`` continues a published
    ``RandomState().get_state()`` tuple ('MT19937', keys (624,), pos,
    has_gauss, gauss).  Draws: ``standard_normal(size)`` (float64),
    ``uniform(low, high, size)``, ``random(size)`` in [0, 1).
    """

    def __init__(self, seed=None):
        self.bit_generator = MT19937()
        self.bit_generator._owner = weakref.ref(self)
        self._legacy = np.random.RandomState(self.bit_generator)
        if seed is not None:
            self._legacy.seed(seed)

    @classmethod
    def from_legacy_state(cls, state):
        """The generator continuing the legacy 5-tuple ``state`` or the dict of ``get_state(legacy=False)``."""
        generator = cls()
        generator._legacy.set_state(state)
        return generator

    def get_state(self):
        """The legacy state tuple ('MT19937', keys, pos, has_gauss, gauss), as the published code pickles it."""
        return self._legacy.get_state()

    def standard_normal(self, size=None):
        return self._legacy.standard_normal(size)

    def normal(self, loc=0.0, scale=1.0, size=None):
        return self._legacy.normal(loc, scale, size)

    def uniform(self, low=0.0, high=1.0, size=None):
        return self._legacy.uniform(low, high, size)

    def random(self, size=None):
        return self._legacy.random_sample(size)

    def integers(self, low, high=None, size=None):
        return self._legacy.randint(low, high, size)


@contextlib.contextmanager
def drawn_by_numpy_global(rng):
    """Within the block, numpy's global legacy stream (``np.random.rand``, ``np.random.seed``...) is ``rng``.

    A user's override written for the published code draws from numpy's global stream (the published
    ``bacteria_run_and_tumble`` starts its tumbles with ``np.random.rand(1)``), which the published code seeds
    with ``seed`` and shares with its Brownian noise.  For a :class:`PublishedGenerator` the global stream takes
    ``rng``'s state on entry and ``rng`` continues where the block's draws left it on exit (the global stream
    gets its own state back), so a published run's draws repeat in the same order.  For any other generator
    (or None) nothing is shared: the block draws from the global stream as it is.
    """
    if not isinstance(rng, PublishedGenerator):
        yield
        return
    own = np.random.get_state()
    np.random.set_state(rng.get_state())
    try:
        yield
    finally:
        rng._legacy.set_state(np.random.get_state())
        np.random.set_state(own)


def make(kind, seed=None):
    """A new generator of ``kind`` ('default' or 'published') seeded by ``seed`` (None: from the system)."""
    if kind == 'published':
        return PublishedGenerator(seed)
    return np.random.default_rng(seed)


def is_legacy_state(state):
    """Whether ``state`` (a ``bit_generator.state`` dict) is the legacy state of a published generator."""
    return isinstance(state, dict) and 'has_gauss' in state


def from_state(state):
    """A new generator continuing ``state`` (a ``bit_generator.state`` dict, as a run state holds it).

    The legacy state of a published generator (``is_legacy_state``: with the cached Gaussian) gives a
    :class:`PublishedGenerator`; any other gives ``numpy.random.Generator`` on the bit generator the state names
    (PCG64, MT19937, ...).  Drawing from it gives the numbers the generator whose state it is would have drawn.
    """
    if is_legacy_state(state):
        generator = PublishedGenerator()
        generator.bit_generator.state = state
        return generator
    name = state.get('bit_generator') if isinstance(state, dict) else None
    bit_generator_class = getattr(np.random, str(name), None)
    if not (isinstance(bit_generator_class, type) and issubclass(bit_generator_class, np.random.BitGenerator)):
        raise ValueError('not the state of a numpy bit generator: %r' % (name,))
    bit_generator = bit_generator_class(0)
    bit_generator.state = state
    return np.random.Generator(bit_generator)
