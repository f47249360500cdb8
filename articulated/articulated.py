"""``articulated.articulated``: the published class of an articulated body, as a face for users' files (top floor).

Override files written for the published package import it (``from articulated.articulated import *``) and may
patch ``Articulated.update_links``.  The package's joints (``multi_bodies.solver.articulated``) take the links of
the velocity solve from the published ``Constraint`` objects (``constraint.constraint``), one per joint; when a
user's file patches ``Articulated.update_links``, the run makes one object of this class per articulated body and
restores the joints after every move with the body-frame links its ``update_links(time)`` leaves in
``constraints_links`` (Nc, 6), as the published code does (``multi_bodies.solver.published_joints``).  The package
never imports this module.
"""
import numpy as np

from constraint.constraint import Constraint  # noqa: F401  (published files import both names from here)


class Articulated(object):
    """The bodies and joints of one articulated body (attributes as published; a patched ``update_links`` reads
    them)."""

    def __init__(self, bodies, ind_bodies, constraints, ind_constraints, num_bodies, num_constraints,
                 constraints_bodies, constraints_links, constraints_extra):
        self.bodies = bodies
        self.ind_bodies = ind_bodies
        self.constraints = constraints
        self.ind_constraints = ind_constraints
        self.num_bodies = num_bodies
        self.num_constraints = num_constraints
        self.constraints_bodies_indices = constraints_bodies
        self.constraints_links = constraints_links
        self.constraints_links_updated = np.copy(constraints_links)
        self.constraints_extra = constraints_extra

    def update_links(self, time=0):
        """Every joint's ``update_links(time)``."""
        for c in self.constraints:
            c.update_links(time=time)
