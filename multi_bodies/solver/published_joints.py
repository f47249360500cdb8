"""The joints of a run driven by the user's published-style ``Constraint`` class (floor 4; doc/articulated.md).

Override files written for the published package patch the class of ``constraint.constraint`` (the published
face): ``update_links(self, time)`` sets the body-frame links ``self.links`` (6,) and the lab-frame time derivatives
``self.links_deriv_updated`` (6,) (usually ``R links_deriv``) from the extra fields of the joint's ``.const`` line
(``self.constraint_extra``, a list of strings), and ``tumbling_event(self, t)`` changes the object's state at the
start of every step (the published ``bacteria_run_and_tumble``).  They may also patch ``Articulated.update_links``
of ``articulated.articulated``, which sets ``self.constraints_links`` (Nc, 6): the published code restores the
joints after every move with those links and solves for the velocities with the ``Constraint`` ones (the
run-and-tumble override gives the two different tilts during a tumble).  :func:`attach` makes one object of the
user's class per joint (and one ``Articulated`` per articulated body when its ``update_links`` is patched) and makes
the :class:`~multi_bodies.solver.articulated.ArticulatedSet` read its links from them (``link_override``,
``position_link_override``) and call ``tumbling_event`` once per step (``step_event``).  The prescribed joint
velocities are read from ``links_deriv_updated``, as the published solve reads them (the run-and-tumble override
zeroes it after a tumble and leaves ``links_deriv`` at its last value).  This module never imports the faces: the
classes come from the user's file (``PhysicsHooks.published_constraint_class``, ``published_articulated_class``).
"""
import numpy as np

from body.geometry import Quaternion
from multi_bodies.solver.user_hooks import call_user_function


class _BodyFrame:
    """What a published ``Constraint`` sees of a body: ``location`` (3,) 0 and ``orientation`` the identity, so
    its ``links_updated`` are the body-frame links (the package rotates them to the lab frame itself)."""

    def __init__(self):
        self.location = np.zeros(3)
        self.orientation = Quaternion(np.array([1.0, 0.0, 0.0, 0.0]))


def attach(articulated, constraint_class=None, articulated_class=None, joint_class=None):
    """Joint objects for every joint of ``articulated``; returns the list.

    ``constraint_class``: the user's patched ``Constraint`` (None: the joints keep the package's own links for the
    solve); each joint object is ``cls([body_p, body_q], [p, q], group, links (6,), constraint_extra)`` with the
    ``.const`` line's extra fields as strings (``[]`` when there are none), ``cls`` the patched class or
    ``joint_class`` (the unpatched one, when only ``Articulated.update_links`` is patched).
    ``articulated_class``: the user's ``Articulated`` with a patched ``update_links``, or None; one object per
    articulated body, ``cls(bodies, ind_bodies, constraints, ind_constraints, num_bodies, num_constraints,
    constraints_bodies (nc, 2) local, constraints_links (nc, 6), constraints_extra)`` as published.
    """
    group_of = np.zeros(articulated.num_constraints, dtype=int)
    for k, group in enumerate(articulated.groups):
        group_of[group.constraint_indices] = k
    extras = [list(extra[0]) if extra is not None else [] for extra in articulated.extras]
    cls = constraint_class if constraint_class is not None else joint_class
    joints = []
    for c in range(articulated.num_constraints):
        joints.append(call_user_function(cls, 'Constraint.__init__', [_BodyFrame(), _BodyFrame()],
                                         np.array(articulated.bodies[c]), int(group_of[c]),
                                         articulated.reference_links[c].copy(), list(extras[c])))

    if constraint_class is not None:
        def published_links(t, links, rates):
            """Body-frame links and rates (Nc, 6) at time ``t`` from every joint's ``update_links(time=t)``."""
            for c, joint in enumerate(joints):
                call_user_function(type(joint).update_links, 'Constraint.update_links', joint, time=t)
                links[c] = np.asarray(joint.links, dtype=float).reshape(6)
                # the lab-frame rates of the published solve; the body frames here are the identity
                rates[c] = np.asarray(joint.links_deriv_updated, dtype=float).reshape(6)
            return links, rates
        articulated.link_override = published_links
    if articulated_class is not None:
        bodies_of = []
        for k, group in enumerate(articulated.groups):
            indices = group.constraint_indices
            bodies_of.append(call_user_function(
                articulated_class, 'Articulated.__init__', [_BodyFrame() for _ in group.body_indices],
                np.array(group.body_indices), [joints[c] for c in indices], np.array(indices),
                int(group.body_indices.size), int(indices.size), np.array(group.local_bodies),
                articulated.reference_links[indices].copy(), [list(extras[c]) for c in indices]))

        def published_position_links(t, links):
            """Body-frame links (Nc, 6) the joints hold at time ``t``: every ``Articulated.update_links(time=t)``."""
            for group, body in zip(articulated.groups, bodies_of):
                call_user_function(type(body).update_links, 'Articulated.update_links', body, time=t)
                links[group.constraint_indices] = np.asarray(body.constraints_links, dtype=float).reshape(-1, 6)
            return links
        articulated.position_link_override = published_position_links
    if callable(getattr(cls, 'tumbling_event', None)):
        def tumbling_events(t):
            """Every joint's ``tumbling_event(t)``, at the start of the step that begins at time ``t``."""
            for joint in joints:
                call_user_function(type(joint).tumbling_event, 'Constraint.tumbling_event', joint, t)
        articulated.step_event = tumbling_events
    return joints
