"""``constraint.constraint``: the published class of one joint, as a face for users' override files (top floor).

Override files written for the published package import it (``from constraint.constraint import *``) and patch
the class: ``Constraint.__init__`` (extra attributes), ``Constraint.update_links(self, time)`` (links that change
in time, from the extra fields of the ``.const`` line, ``constraint_extra``) and ``Constraint.tumbling_event(self,
t)`` (called at the start of every step).  The package never imports this module; when a user's file has patched
its class, the run makes one object per joint (``multi_bodies.solver.published_joints``) and takes the joints'
links from them:

* ``links`` (6,): the body-frame links ``[l_p, l_q]`` (length units) after ``update_links(time)``;
* ``links_deriv`` (6,): their time derivatives (length / time); the solve reads the prescribed joint velocities
  from ``links_deriv_updated`` (6,), as published (``update_links`` sets it to ``R links_deriv``);
* ``bodies``: the two bodies, each with ``location`` (3,) and ``orientation`` (``rotation_matrix()`` (3, 3)).
"""
import numpy as np


class Constraint(object):
    """One joint between bodies ``ind_bodies`` (p, q) of articulated body ``articulated_body``."""

    def __init__(self, bodies, ind_bodies, articulated_body, links, constraint_extra=None):
        self.bodies = bodies
        self.ind_bodies = ind_bodies
        self.articulated_body = articulated_body
        self.links = np.array(links, dtype=float)
        self.links_updated = np.copy(self.links)
        self.presc_vel = np.zeros(3)
        self.C = None
        self.constraint_extra = [] if constraint_extra is None else constraint_extra
        self.links_deriv = np.zeros(6)
        self.links_deriv_updated = np.zeros(6)

    def update_links(self, time=0):
        """The links in the lab frame (``links_updated``, ``links_deriv_updated``) at the bodies' orientations."""
        R_p = self.bodies[0].orientation.rotation_matrix()
        R_q = self.bodies[1].orientation.rotation_matrix()
        self.links_updated[0:3] = R_p @ self.links[0:3]
        self.links_updated[3:6] = R_q @ self.links[3:6]
        self.links_deriv_updated[0:3] = R_p @ self.links_deriv[0:3]
        self.links_deriv_updated[3:6] = R_q @ self.links_deriv[3:6]

    def calc_constraint_violation(self, time_point='current'):
        """``g = q_p + R_p l_p - q_q - R_q l_q`` (3,) at the bodies' current locations and orientations."""
        g = np.asarray(self.bodies[0].location, dtype=float) - np.asarray(self.bodies[1].location, dtype=float)
        g = g + self.bodies[0].orientation.rotation_matrix() @ self.links[0:3]
        return g - self.bodies[1].orientation.rotation_matrix() @ self.links[3:6]
