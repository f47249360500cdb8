'''
Physics of the boomerang suspension written in the style of the published
package (accepted here for compatibility): the file imports the module of
the default hooks, defines new functions of one blob, one blob pair and one
body pair, and rebinds the module attributes.  The laws are those of
../user_defined_functions.py:

1. blob-wall: U = eps a exp(-(h - a)/b) / (h - a), plus gravity
   (eps = repulsion_strength_wall, b = debye_length_wall, h = blob height);
2. blob-blob: U = eps 2a exp(-(r - 2a)/b) / r
   (eps = repulsion_strength, b = debye_length);
3. body-body: a spring U = k (r - l0)^2 / 2 between the tracking points,
   k = 1e-3, l0 = 1, no torque.

These functions take one blob (one pair) at a time, so the code calls them
in a Python loop: slower than the vectorised functions of
../user_defined_functions.py, same numbers.
'''
import multi_bodies_functions
from multi_bodies_functions import *


def blob_external_force_new(r_vectors, *args, **kwargs):
  '''
  Force on one blob at r_vectors (shape (3,)): gravity and the wall potential.
  Heights closer to contact than 1e-3 a are treated as 1e-3 a above contact.
  '''
  g = kwargs.get('g')
  blob_mass = kwargs.get('blob_mass')
  a = kwargs.get('blob_radius')
  eps = kwargs.get('repulsion_strength_wall')
  b = kwargs.get('debye_length_wall')
  gap = max(r_vectors[2] - a, 1e-3 * a)
  f = np.zeros(3)
  f[2] = -g * blob_mass + eps * a * np.exp(-gap / b) * (1.0 / (b * gap) + 1.0 / gap**2)
  return f
multi_bodies_functions.blob_external_force = blob_external_force_new


def blob_blob_force_new(r, *args, **kwargs):
  '''
  Force on blob i from blob j, r = r_j - r_i (shape (3,)).
  '''
  L = kwargs.get('periodic_length')
  eps = kwargs.get('repulsion_strength')
  b = kwargs.get('debye_length')
  d = 2.0 * kwargs.get('blob_radius')
  project_to_periodic_image(r, L)
  distance = max(np.linalg.norm(r), 1e-12)
  dU_dr = -eps * d * np.exp(-(distance - d) / b) * (1.0 / (b * distance) + 1.0 / distance**2)
  return dU_dr * r / distance
multi_bodies_functions.blob_blob_force = blob_blob_force_new


def body_body_force_torque_new(r, quaternion_i, quaternion_j, *args, **kwargs):
  '''
  Force and torque on body i from body j, r = location_j - location_i.
  Returns an array of shape (2, 3): force, torque.
  '''
  stiffness = 1e-3
  rest_length = 1.0
  L = kwargs.get('periodic_length')
  project_to_periodic_image(r, L)
  distance = max(np.linalg.norm(r), 1e-12)
  force_torque = np.zeros((2, 3))
  force_torque[0] = stiffness * (distance - rest_length) * r / distance
  return force_torque
multi_bodies_functions.body_body_force_torque = body_body_force_torque_new
