"""Every contact of the robot counted, timed for as long as it lasts, and shared out step by step.

A contact is the robot touching one object — the static world counts as one object (sliding along
a wall built of several map boxes is one contact), each mover as one — from the physics step in
which it starts touching it to the one in which it stops; touching the same object again within
REJOIN_S continues that contact (a mover pushing the robot along separates from it and meets it
again substep after substep: one push, not fifty contacts). Every physics substep of a contact is
judged on its own (Simulation decides, this ledger adds up): the substep is the robot's when the
robot moved towards the contact point at any speed, or when it stayed in a mover's way although
it had seen the mover coming; otherwise the mover's (it walked into a robot standing or leaving,
or shoved it into a wall). A contact with at least one substep of the robot's counts as the
robot's; contact-seconds are summed over substeps in which the robot touched anything.

BARN's rule — any contact fails a run — reads `contacts`; the shares are reported beside it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STATIC = -1          # what a contact touched when it is no mover
REJOIN_S = 0.1       # s: touching an object again this soon continues the contact


@dataclass
class Contact:
    """One contact: the robot touching `touched` (a mover's index, or STATIC)."""
    touched: int
    began_s: float
    foreseen: bool = False      # a mover the robot could have seen coming (Simulation's foresight)
    shoved: bool = False        # a static contact begun while a mover touched the robot
    seconds: float = 0.0
    robot_seconds: float = 0.0


class ContactLedger:
    """Contacts as they begin, last and end, and the totals a run is judged by."""

    def __init__(self) -> None:
        self.open: dict[int, Contact] = {}
        self._ended: dict[int, tuple[Contact, float]] = {}    # object -> its last contact, when it ended
        self.contacts = 0               # contacts begun
        self.robot_contacts = 0         # of those, with at least one substep of the robot's
        self.shoved_contacts = 0        # static contacts begun while a mover touched the robot
        self.contact_s = 0.0            # s in which the robot touched anything
        self.robot_contact_s = 0.0      # s in which some contact was the robot's
        self.longest_s = 0.0            # the longest single contact so far

    @property
    def mover_contacts(self) -> int:
        """Contacts with no substep of the robot's: the movers' share."""
        return self.contacts - self.robot_contacts

    def begin(self, touched: int, now_s: float, *, foreseen: bool = False) -> None:
        last, ended_s = self._ended.pop(touched, (None, -float("inf")))
        if last is not None and now_s - ended_s <= REJOIN_S:
            self.open[touched] = last
            return
        shoved = touched == STATIC and any(k != STATIC for k in self.open)
        self.open[touched] = Contact(touched, now_s, foreseen=foreseen, shoved=shoved)
        self.contacts += 1
        self.shoved_contacts += shoved

    def end(self, touched: int, now_s: float) -> None:
        contact = self.open.pop(touched, None)
        if contact is not None:
            self._ended[touched] = (contact, now_s)

    def substep(self, robots: dict[int, bool], dt: float) -> None:
        """One physics substep of dt in which the robot touched the objects of `robots`, each
        mapped to whether this substep of that contact was the robot's."""
        if not robots:
            return
        self.contact_s += dt
        if any(robots.values()):
            self.robot_contact_s += dt
        for touched, robots_share in robots.items():
            contact = self.open.get(touched)
            if contact is None:         # touching without a begin: pymunk reports pairs, not objects
                continue
            if robots_share and contact.robot_seconds == 0.0:
                self.robot_contacts += 1
            contact.seconds += dt
            contact.robot_seconds += dt if robots_share else 0.0
            self.longest_s = max(self.longest_s, contact.seconds)


class MoverHistory:
    """The movers' positions and velocities over the last `steps` steps, for judging whether a
    contact could have been seen coming (Simulation's foresight)."""

    def __init__(self, steps: int, movers: int) -> None:
        self.xy = np.zeros((steps, movers, 2))
        self.velocity = np.zeros((steps, movers, 2))
        self.count = 0

    def push(self, xy: np.ndarray, velocity: np.ndarray) -> None:
        slot = self.count % len(self.xy)
        self.xy[slot], self.velocity[slot] = xy, velocity
        self.count += 1

    def oldest(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The movers `steps` steps ago, None before that many steps were pushed."""
        if self.count < len(self.xy):
            return None
        slot = self.count % len(self.xy)
        return self.xy[slot], self.velocity[slot]
