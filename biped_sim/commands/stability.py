"""``biped-sim stability``: the stability suite (stability.py)."""
from __future__ import annotations


def register(sub):
    p = sub.add_parser("stability", help="stability suite (work in progress)")
    p.set_defaults(func=lambda args: 0)
