"""What Python and the compiled drivers (``simulation/c/``) must agree on, declared once here and
printed as C: the options struct every driver takes (:class:`DriverOptions`, C ``kronlag_options``)
and the codes they return (``KRONLAG_RESULT_<NAME>`` from :class:`~.trajectory.Result`,
``KRONLAG_HANDBACK``).  :func:`c_declarations` goes before the drivers' C in the source
:mod:`.drivers` compiles, so a field or a code changed here changes on both sides.

A driver is ``int kronlag_<name>(kronlag_options *options)``: it reads the ``in`` fields and
writes the ``out`` fields and buffers; the fields a driver does not use are left alone (zero).
"""

from __future__ import annotations

import ctypes
from functools import cache

import numpy as np

from .trajectory import Result

__all__ = ["FIELDS", "DriverOptions", "Progress", "GapFunction", "Controller", "HANDBACK", "c_declarations",
           "c_declaration", "doubles"]


#: ``progress(t)`` after accepted steps (a NULL pointer: none): 0 to go on, or the
#: ``KRONLAG_RESULT_<NAME>`` code to end the run with (``INTERRUPTED``: Ctrl-C; ``RAISED``).
Progress = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double)

#: ``controller(t)`` of a controlled run (:mod:`.controllers`), after the driver wrote ``[q, qd]`` to
#: ``control_buffer``: the controller writes ``p_control``; returns 0, or the code to end the run with.
Controller = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double)

#: A segment that ends because the motion is clear of a singular configuration, for the switching
#: method to continue with the fast method (positive like :attr:`Result.APPROACH`, the hand-over the
#: other way; not a :class:`Result`: the integration goes on).
HANDBACK = 1

_DOUBLES = ctypes.POINTER(ctypes.c_double)

#: ``gaps(q, p, g)``: the gaps of the limit sides (:mod:`kronlag.numeric.limit_kernels`).
GapFunction = ctypes.CFUNCTYPE(None, _DOUBLES, _DOUBLES, _DOUBLES)
_D, _I, _L = ctypes.c_double, ctypes.c_int, ctypes.c_long

#: The fields of :class:`DriverOptions`: name, ctypes type, ``"in"`` (set by Python; pointers are
#: ``const`` in C) or ``"out"`` (written by the driver), and what the field holds.  Shapes: m
#: coordinates, r holonomic and s nonholonomic constraints, ``rows = max_rows``.  The outputs from
#: ``qdd`` to ``velocity_residual`` are named as in :attr:`~.problem.Solution.derived`.
FIELDS: tuple[tuple[str, type, str, str], ...] = (
    ("p", _DOUBLES, "in", "parameter vector (n_parameters)"),
    ("n_parameters", _I, "in", "length of p"),
    ("t0", _D, "in", "start time"),
    ("t1", _D, "in", "end time"),
    ("y0", _DOUBLES, "in", "consistent start [q0, qd0] (2 m)"),
    ("a0", _DOUBLES, "in", "accelerations at the start (m; index-3 driver)"),
    ("lam0", _DOUBLES, "in", "multipliers at the start (r; index-3 driver)"),
    ("alpha", _D, "in", "Baumgarte alpha (index-1 driver)"),
    ("beta", _D, "in", "Baumgarte beta (index-1 driver)"),
    ("rtol", _D, "in", "relative local error tolerance"),
    ("atol", _D, "in", "absolute local error tolerance"),
    ("projection_tol", _D, "in", "residual tolerance of the projection of the outputs (index-1 driver)"),
    ("h0", _D, "in", "first step (0: the driver's choice)"),
    ("max_step", _D, "in", "largest step (0: unbounded)"),
    ("max_steps", _L, "in", "most accepted steps"),
    ("max_order", _I, "in", "highest order of a variable-order method (0: all it has)"),
    ("handback", _I, "in", "nonzero: end with KRONLAG_HANDBACK once clear of a singular configuration"),
    ("row_scale", _DOUBLES, "in", "the constraint rows' units in the approach test (r; NULL: their norms at t0)"),
    ("progress", Progress, "in", "called with t after accepted steps (NULL: not); nonzero: the code to end with"),
    ("progress_interval", _D, "in", "seconds between progress calls (0: after every accepted step)"),
    ("n_eval", _I, "in", "number of output times (0: every step is an output)"),
    ("t_eval", _DOUBLES, "in", "output times (n_eval), increasing"),
    ("max_rows", _I, "in", "rows of the output buffers"),
    ("t_out", _DOUBLES, "out", "output times (rows)"),
    ("y_out", _DOUBLES, "out", "[q, qd] at the outputs (rows x 2 m)"),
    ("qdd", _DOUBLES, "out", "accelerations (rows x m)"),
    ("lam", _DOUBLES, "out", "holonomic multipliers (rows x r)"),
    ("mu", _DOUBLES, "out", "nonholonomic multipliers (rows x s)"),
    ("kinetic_energy", _DOUBLES, "out", "kinetic energy (rows)"),
    ("potential_energy", _DOUBLES, "out", "potential energy (rows)"),
    ("position_residual", _DOUBLES, "out", "position residual Phi (rows x r)"),
    ("velocity_residual", _DOUBLES, "out", "velocity residual [Phi_q qd + Phi_t; A qd + b] (rows x (r + s))"),
    ("n_out", _I, "out", "rows written"),
    ("events", _DOUBLES, "out", "singular passages (max_events x (5 + m), monitor.c)"),
    ("max_events", _I, "in", "rows of events"),
    ("n_events", _I, "out", "passages seen (more than max_events are counted, not stored)"),
    ("t_end", _D, "out", "where the segment ended"),
    ("y_end", _DOUBLES, "out", "state there (2 m)"),
    ("steps", _L, "out", "accepted steps"),
    ("nfev", _L, "out", "right-hand sides (index 1) or Newton iterations (index 3)"),
    ("njev", _L, "out", "Jacobians"),
    ("lowest_order", _I, "out", "lowest order used by a variable-order driver (0: a fixed-order one)"),
    ("highest_order", _I, "out", "highest order used by a variable-order driver (0: a fixed-order one)"),
    # limits (kronlag.simulation.impacts, c/limits.c): the watched functions, the segment ends at a root
    ("gaps", GapFunction, "in", "the limit sides' gaps g(q, gap_parameters) (NULL: no limits)"),
    ("gap_parameters", _DOUBLES, "in", "parameters of gaps"),
    ("n_gaps", _I, "in", "number of limit sides"),
    ("gap_watched", _DOUBLES, "in", "1: the side's gap is watched, 0: it is held as a constraint (n_gaps)"),
    ("n_contacts", _I, "in", "contact constraints whose force -lam is watched"),
    ("contact_rows", _DOUBLES, "in", "their rows of lam (n_contacts)"),
    ("roots", _DOUBLES, "out", "1 for each watched function that fell through zero (n_gaps + n_contacts)"),
    # exact stiction: sliding directions turned inside the run at kinematic dead points (c/cvode.c kl_turn)
    ("max_turns", _I, "in", "rows of turns (0: every stiction event ends the segment)"),
    ("at_rest", _D, "in", "a sliding joint's rate within this is at rest (an event for Python then)"),
    ("turns", _DOUBLES, "out", "per joint turned: t, the joint's index, [q, qd] before and after the "
     "projection there (max_turns x (2 + 4 m))"),
    ("n_turns", _I, "out", "rows of turns written"),
    # a controller in the loop (simulation/controllers.py, c/controller.c)
    ("controller", Controller, "in", "called with t after [q, qd] were written to control_buffer (NULL: none)"),
    ("control_mode", _I, "in", "0: no controller; 1: called at every evaluation; 2: at the sample instants"),
    ("p_control", _DOUBLES, "out", "the parameters the kernels read under a controller (n_parameters)"),
    ("control_buffer", _DOUBLES, "out", "[q, qd] for the controller, then the next sample instant (2 m + 1)"),
    ("p_out", _DOUBLES, "out", "the parameters at each output under a controller (rows x n_parameters)"),
)


def _is_pointer(ctype) -> bool:
    return isinstance(ctype, type) and issubclass(ctype, ctypes._Pointer)


class DriverOptions(ctypes.Structure):
    """The one argument of every compiled driver (C ``kronlag_options``): inputs, output buffers
    and counters, the fields of :data:`FIELDS`.

    A data pointer is stored as ``c_void_p`` (the same size and alignment as the ``double *`` of
    the C declaration), so that it is set from an address (:func:`doubles`) without building a
    ctypes pointer object per array and call.
    """

    _fields_ = [(name, ctypes.c_void_p if _is_pointer(ctype) else ctype) for name, ctype, _, _ in FIELDS]


def doubles(array: np.ndarray) -> int:
    """The address of the data of the C-contiguous float64 ``array``, for a ``double *`` field (the
    caller keeps ``array`` alive while the driver runs)."""
    return array.ctypes.data


#: C names of the ctypes scalars the drivers use (``None``: a function that returns nothing).
_C_NAMES = {ctypes.c_double: "double", ctypes.c_int: "int", ctypes.c_long: "long", None: "void"}


def c_declaration(ctype, name: str, const: bool = False) -> str:
    """The C declaration of ``name`` with the ctypes type ``ctype`` (a scalar of :data:`_C_NAMES`,
    a pointer to one, or a ``CFUNCTYPE``); ``const``: a pointer to constant data."""
    if _is_pointer(ctype):
        return c_declaration(ctype._type_, f"*{name}", const)
    if isinstance(ctype, type) and issubclass(ctype, ctypes._CFuncPtr):
        arguments = ", ".join(c_declaration(argument, "").strip() for argument in ctype._argtypes_) or "void"
        return c_declaration(ctype._restype_, f"(*{name})({arguments})")
    return f"{'const ' if const else ''}{_C_NAMES[ctype]} {name}"


@cache
def c_declarations() -> str:
    """The result codes, :data:`HANDBACK` and the typedef of ``kronlag_options``, as C."""
    codes = [member.code for member in Result]
    if len(set(codes)) < len(codes) or HANDBACK in codes:
        raise ValueError(f"a driver code with two meanings: {codes}, handback {HANDBACK}")
    lines = ["/* Generated by kronlag.simulation.interface: the codes and the options of the drivers. */"]
    lines += [f"#define KRONLAG_RESULT_{member.name} ({member.code})" for member in Result]
    lines += [f"#define KRONLAG_HANDBACK ({HANDBACK})", "typedef struct {"]
    for name, ctype, role, text in FIELDS:
        declaration = c_declaration(ctype, name, const=_is_pointer(ctype) and role == "in")
        lines.append(f"    {declaration};  /* {role}: {text} */")
    lines.append("} kronlag_options;")
    return "\n".join(lines) + "\n"
