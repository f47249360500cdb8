"""The sphere of the libMobility tests and its analytic self-mobility above a wall.

Not a test module: ``tests/test_libmobility.py`` and ``tests/test_libmobility_dpstokes.py`` import it.
"""
import numpy as np


ETA = 0.7
RADIUS = 0.9


def _wall_self_mobility(h, a=RADIUS, eta=ETA):
    """Rotne-Prager-Blake self-mobility (6, 6) of one sphere at height h >= a above a no-slip wall
    (Swan and Brady 2007): diagonal translation and rotation terms; the coupling is not asserted here."""
    x = a / h
    mu_t, mu_r = 1 / (6 * np.pi * eta * a), 1 / (8 * np.pi * eta * a ** 3)
    parallel = mu_t * (1 - 9 / 16 * x + 1 / 8 * x ** 3 - 1 / 16 * x ** 5)
    perpendicular = mu_t * (1 - 9 / 8 * x + 1 / 2 * x ** 3 - 1 / 8 * x ** 5)
    rot_parallel = mu_r * (1 - 5 / 16 * x ** 3)
    rot_perpendicular = mu_r * (1 - 1 / 8 * x ** 3)
    return np.array([parallel, parallel, perpendicular, rot_parallel, rot_parallel, rot_perpendicular])
