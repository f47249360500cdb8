"""The joints of a run driven by the user's published-style ``Constraint`` class (floor 4; doc/articulated.md).

Override files written for the published package patch the class of ``constraint.constraint`` (the published
face): ``update_links(self, time)`` sets the body-frame links ``self.links`` (6,) and their time derivatives
``self.links_deriv`` (6,) from the extra fields of the joint's ``.const`` line (``self.constraint_extra``, a
list of strings), and ``tumbling_event(self, t)`` changes the object's state at the start of every step (the
published ``bacteria_run_and_tumble``).  :func:`attach` makes one object of the user's class per joint and
makes the :class:`~multi_bodies.solver.articulated.ArticulatedSet` read its links from them (``link_override``)
and call ``tumbling_event`` once per step (``step_event``).  This module never imports the face: the class
comes from the user's file (``PhysicsHooks.published_constraint_class``).
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


def attach(articulated, constraint_class):
    """Joint objects of ``constraint_class`` for every joint of ``articulated``; returns the list.

    Each object is ``constraint_class([body_p, body_q], [p, q], group, links (6,), constraint_extra)`` with the
    ``.const`` line's extra fields as strings (``[]`` when there are none).
    """
    group_of = np.zeros(articulated.num_constraints, dtype=int)
    for k, group in enumerate(articulated.groups):
        group_of[group.constraint_indices] = k
    joints = []
    for c in range(articulated.num_constraints):
        extra = articulated.extras[c]
        joints.append(call_user_function(constraint_class, 'Constraint.__init__', [_BodyFrame(), _BodyFrame()],
                                         np.array(articulated.bodies[c]), int(group_of[c]),
                                         articulated.reference_links[c].copy(),
                                         list(extra[0]) if extra is not None else []))

    def published_links(t, links, rates):
        """Body-frame links and rates (Nc, 6) at time ``t`` from every joint's ``update_links(time=t)``."""
        for c, joint in enumerate(joints):
            call_user_function(type(joint).update_links, 'Constraint.update_links', joint, time=t)
            links[c] = np.asarray(joint.links, dtype=float).reshape(6)
            rates[c] = np.asarray(joint.links_deriv, dtype=float).reshape(6)
        return links, rates
    articulated.link_override = published_links
    if callable(getattr(constraint_class, 'tumbling_event', None)):
        def tumbling_events(t):
            """Every joint's ``tumbling_event(t)``, at the start of the step that begins at time ``t``."""
            for joint in joints:
                call_user_function(type(joint).tumbling_event, 'Constraint.tumbling_event', joint, t)
        articulated.step_event = tumbling_events
    return joints
