"""The physical terms a scene may list, one module each, and their registry ``TERMS``.

Folded into the node update: ``gravity``, ``loads`` (constant loads), ``damping``, ``fixity``
(``clamps``, ``constraints``), ``drives``; the plane pass: ``planes`` (``plates``, ``walls``); per-step
terms of the step loop's chain: ``contact`` (``contact``, ``friction``) and any registered term with
an ``eval`` (:mod:`fiberpipe.solver.terms.base` gives the shape).
"""

from . import contact, damping, drives, fixity, gravity, loads, planes  # noqa: F401  (register the built-in terms)
from .base import TERMS, ContactHook, SceneArrays, Term, TermKernels, no_eval, no_forces, register_term
from .damping import Damping
from .drives import Drive, Drives
from .fixity import AxialLock, Clamp, Clamps
from .gravity import Gravity
from .loads import LineLoad, Loads, PointLoad
from .planes import Plates, Walls

__all__ = ["TERMS", "ContactHook", "SceneArrays", "Term", "TermKernels", "no_eval", "no_forces", "register_term",
           "Damping", "Drive", "Drives", "AxialLock", "Clamp", "Clamps", "Gravity", "LineLoad", "Loads", "PointLoad",
           "Plates", "Walls"]
