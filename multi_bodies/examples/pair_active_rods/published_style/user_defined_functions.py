'''
The active slip of the pair of rods, written in the style of the published
package (accepted here for compatibility): import the module of the default
hooks, define a new function and rebind the module attribute.

The slip is the same as in ../user_defined_functions.py: speed 20 along the
rod axis towards the nearest end, on the blobs within 0.8 of an end.
'''
import multi_bodies_functions
from multi_bodies_functions import *


def set_slip_by_ID_new(body, slip):
  '''
  Rods (ID 'rods', the name of their clones file) get the extensile slip;
  the other bodies get the slip of their slip file, or none.
  '''
  if body.ID == 'rods':
    body.function_slip = slip_extensile_rod
  elif slip is not None:
    body.function_slip = partial(active_body_slip, slip = slip)
  else:
    body.function_slip = default_zero_blobs
  return
multi_bodies_functions.set_slip_by_ID = set_slip_by_ID_new


def slip_extensile_rod(body):
  '''
  Slip of a straight rod, one blob at a time: blobs near an end move the
  fluid along the axis towards that end; the middle blobs are passive.
  '''
  speed = 20.0
  active_length = 0.8
  r_vectors = body.get_r_vectors()
  axis = r_vectors[body.Nblobs - 1] - r_vectors[0]
  half_length = 0.5 * (np.linalg.norm(axis) + 2.0 * body.blob_radius)
  axis = axis / np.linalg.norm(axis)
  slip = np.zeros((body.Nblobs, 3))
  for i in range(body.Nblobs):
    distance = np.dot(r_vectors[i] - body.location, axis)
    if distance > half_length - active_length:
      slip[i] = speed * axis
    elif distance < -(half_length - active_length):
      slip[i] = -speed * axis
  return slip
