"""The published override module: ``import multi_bodies_functions`` in a user's file.

Published ``user_defined_functions.py`` files start with
``import multi_bodies_functions`` and ``from multi_bodies_functions import *``
and rebind ``multi_bodies_functions.X = X_new`` (see doc/overrides.md).  This
module gives them every name they expect: the default physics hooks and the
published helpers, the names such files take from a star import (``np``,
``partial``, ``Quaternion``) and the loader of user files
(:mod:`multi_bodies.solver.user_hooks`).

The definitions are those of :mod:`multi_bodies.solver.physics`, executed
in this module's own namespace (not imported), so that, as in the published
code, rebinding a name here changes what this module's helpers call
(``force_torque_calculator_sort_by_bodies`` calls this module's
``calc_one_blob_forces``, which calls its ``blob_external_forces``) while the
package's own physics stays untouched.

The package never imports this module: it sits on the scripts' floor.  The
loader gives each user file a fresh copy of it, so one run's rebindings
never leak into another run in the same process.
"""
import os as _os

_PHYSICS_SOURCE = _os.path.join(_os.path.dirname(_os.path.abspath(__file__)), 'solver', 'physics.py')
with open(_PHYSICS_SOURCE) as _file:
    exec(compile(_file.read(), _PHYSICS_SOURCE, 'exec'))  # the package's own source file, not user data
del _file

from multi_bodies.solver.user_hooks import (PhysicsHooks, UserFunctionError, call_user_function,  # noqa: E402,F401
                                            checked_array, describe_user_function, function_file,
                                            function_name, import_user_file, load_user_hooks,
                                            load_user_pycuda_forces, positional_arity, positional_capacity)
