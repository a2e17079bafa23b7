"""Contacts and grasps: the paper's steps 1 and 2 (section 2.1, Fig. 2).

Takes the hand, the object and its motion. Gives:

- :mod:`.manifold`: each finger's joint-space manifold of the object surface over
  time, with the joint limits as boundary planes (Fig. 2);
- :mod:`.contact`: the contact model (when a contact is usable: inside the limits with
  a margin, the pad facing the surface, the links clear:
  :class:`~regrasp_pin.model.clearance.LinkClearance`);
- :mod:`.tracking` and :mod:`.holding`: a held contact followed by IK over time, when
  its hold ends, and the holding hand's configurations;
- :mod:`.choice`: the initial grasp and the new contact Q (the paper's conditions
  (a) and (b): inside the limits, usable for the longest time);
- :mod:`.quality`: force closure and the Ferrari-Canny epsilon;
- :mod:`.necessity`: the runs of time in which a finger cannot let go (no grasp without
  it exists), and whether any of its contacts lasts through them.
"""

from .choice import NewContact, choose_new_contact, exit_times
from .contact import ContactModel
from .holding import Holding, holding_hand
from .initial import Grasp, initial_grasp
from .manifold import Manifold, build_manifold
from .necessity import MustHold, first_infeasibility, must_hold
from .quality import contact_wrenches, ferrari_canny_epsilon, is_force_closure
from .tracking import ContactTrack, track_contact

__all__ = [
    "ContactModel",
    "ContactTrack",
    "Grasp",
    "Holding",
    "Manifold",
    "MustHold",
    "NewContact",
    "build_manifold",
    "choose_new_contact",
    "contact_wrenches",
    "exit_times",
    "ferrari_canny_epsilon",
    "first_infeasibility",
    "holding_hand",
    "initial_grasp",
    "is_force_closure",
    "must_hold",
    "track_contact",
]
