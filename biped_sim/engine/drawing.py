"""The robot as lines and points, for any chain: what the markers and the animation draw.

Owns :class:`Figure` (the base's joint, each leg's links from the base to its foot, the other links, the
feet) and :class:`RobotDrawing`, which makes it from a model at a state ``q``:

* a ``BipedModel`` (the three-link robots the engine runs): its ``stick_figure`` (hip, feet, torso tip),
  so that its parameters (``model.*``) are drawn as simulated;
* a ``GeneratedModel`` (any description: ``bs.load_model("rabbit")``): the forward kinematics of its links
  (``GeneratedModel.segments``: each link's joint and tip) and its contact points. Leg k is the chain of
  links from the base to the link that carries contact point k (foot k), the base and the links shared
  by the legs left out; every other link (the torso) is the body.

A group of links whose joints sit at their parents' tips, each the parent of the next (a femur and its
tibia), is one polyline (``strip``); any other group is drawn as separate segments (pairs of points).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Lines(NamedTuple):
    """Points in the model's plane (x, y): a polyline if ``strip``, else pairs (one segment each)."""
    points: tuple
    strip: bool


class Figure(NamedTuple):
    """The drawing of one state: ``hip`` the base's joint (the view and the ``hip`` frame follow it),
    ``legs`` one :class:`Lines` per foot (foot 1's first), ``body`` the other links, ``feet`` the contact
    points (x, y), foot 1 first."""
    hip: np.ndarray
    legs: tuple
    body: Lines
    feet: tuple


def from_stick_figure(fig) -> Figure:
    """The :class:`Figure` of a three-link ``StickFigure``: two one-link legs from the hip, the torso."""
    return Figure(fig.hip, (Lines((fig.hip, fig.foot_1), True), Lines((fig.hip, fig.foot_2), True)),
                  Lines((fig.hip, fig.torso_tip), True), (fig.foot_1, fig.foot_2))


def _chain_plan(desc):
    """(per foot: (link indices, strip), body: (link indices, strip)) of a description."""
    by_name = {link.name: i for i, link in enumerate(desc.links)}

    def path(link_name):             # the links from the base out to ``link_name``
        out = []
        while link_name is not None:
            out.append(by_name[link_name])
            link_name = desc.links[by_name[link_name]].parent
        return out[::-1]

    paths = [path(c.link) for c in desc.contacts]
    shared = set.intersection(*(set(p) for p in paths)) if paths else set()
    legs = [[i for i in p if i not in shared] for p in paths]
    on_legs = {i for leg in legs for i in leg}
    body = [i for i in range(len(desc.links)) if i not in on_legs]

    def strip(indices):             # each link hangs at the previous one's tip
        for a, b in zip(indices, indices[1:]):
            parent, child = desc.links[a], desc.links[b]
            if child.parent != parent.name or tuple(child.origin) != (0.0, parent.length):
                return False
        return True
    return [(tuple(leg), strip(leg)) for leg in legs], (tuple(body), strip(body))


def _lines(segments, indices, strip) -> Lines:
    if not indices:
        return Lines((), True)
    if strip:
        return Lines((segments[indices[0], 0], *(segments[i, 1] for i in indices)), True)
    return Lines(tuple(p for i in indices for p in (segments[i, 0], segments[i, 1])), False)


class RobotDrawing:
    """``figure(q)``: the :class:`Figure` of a model at ``q``; ``foot(q, leg)``: contact point ``leg`` (1-based)."""

    def __init__(self, model):
        self.model = model
        self.chain = not hasattr(model, "stick_figure")
        if self.chain:
            self.legs, self.body = _chain_plan(model.description)

    def figure(self, q) -> Figure:
        if not self.chain:
            return from_stick_figure(self.model.stick_figure(q))
        model = self.model
        segments = model.segments(q)
        feet = tuple(model.contact_position(q, k) for k in range(1, len(model.contacts) + 1))
        hip = np.asarray(q, dtype=float)[:2].copy()      # the base link's joint: (base_x, base_y)
        return Figure(hip, tuple(_lines(segments, idx, strip) for idx, strip in self.legs),
                      _lines(segments, *self.body), feet)

    def foot(self, q, leg: int) -> np.ndarray:
        if not self.chain:
            return self.model.foot_position(q, leg)
        return self.model.contact_position(q, leg)
