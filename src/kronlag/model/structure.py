"""The structure report of a :class:`~kronlag.System` (:meth:`kronlag.System.describe`): its bodies,
joints, the constraints that close loops or couple joints, and the Grübler count.

The count here is ``m - r - s`` (coordinates minus constraint rows); the true mobility, from the
rank of ``Phi_q`` at an assembled state, needs numbers: ``kronlag check`` prints it
(:meth:`kronlag.NumericModel.mobility`).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .system import System

__all__ = ["describe"]


def _counted(kinds: Counter) -> str:
    return ", ".join(f"{kind} {count}" for kind, count in sorted(kinds.items()))


def describe(system: System) -> str:
    """A few lines for people: bodies (with masses), joints by kind, loop-closing and coupling
    constraints by name, and the Grübler count ``m - r - s``.

    A system read from a robot file (``system.robot``) lists the file's joints: the moving ones
    (one coordinate each; floating, ball, planar and universal joints several), the fixed ones (merged into a body) and the mimic joints (a constraint);
    each joint that closes a loop with its rows, the frame of their components and its rows dropped.
    The ranks of each joint's or loop's rows at the assembled state need numbers: ``kronlag check``.
    """
    m, r, s = len(system.coordinates), len(system.constraints), len(system.nonholonomic_constraints)
    robot = getattr(system, "robot", None)
    origin = f" ({robot.format.upper()} {Path(robot.source).name})" if robot is not None else ""
    lines = [f"{system.name}{origin}: {len(system.bodies)} bodies, {m} coordinates, {r} holonomic and "
             f"{s} nonholonomic constraints"]
    lines.append("bodies: " + ", ".join(f"{body.name} ({float(body.mass):.6g})" if body.mass.is_number
                                        else body.name for body in system.bodies))
    if robot is not None:
        moving = [joint for joint in robot.joints if joint.coordinate]
        fixed = [joint for joint in robot.joints if not joint.coordinate]
        counts = [len(joint.coordinates) or 1 for joint in moving]
        each = "one coordinate each" if set(counts) <= {1} else f"{sum(counts)} coordinates"
        lines.append(f"joints: {len(moving)} moving ({_counted(Counter(j.kind for j in moving))}), {each}"
                     + (f"; {len(fixed)} fixed, merged: " + ", ".join(
                         f"{j.child} into {robot.body_of_link[j.child]}" for j in fixed) if fixed else ""))
        coupling = [f"{joint.name}.mimic ({joint.name} = {joint.mimic[1]:g} * {joint.mimic[0]} + {joint.mimic[2]:g})"
                    for joint in moving if joint.mimic]
        if coupling:
            lines.append("mimic joints (constraints): " + ", ".join(coupling))
        if robot.redundant:
            lines.append("rows dropped as identically zero (redundant): " + ", ".join(robot.redundant))
    if system.joints:
        lines.append(f"constraint joints: {len(system.joints)} ({_counted(Counter(j.kind for j in system.joints))}): "
                     + ", ".join(f"{joint.name} ({len(joint.constraint_names)} rows)" for joint in system.joints))
    named = {name for joint in system.joints for name in joint.constraint_names}
    for loop in robot.loops if robot is not None else ():
        suffixes = " ".join("." + row.rsplit(".", 1)[1] for row in loop.rows)
        dropped = " ".join("." + row.rsplit(".", 1)[1] for row in loop.dropped)
        lines.append(f"loop closed by {loop.joint} ({loop.kind}, {loop.parent} to {loop.child}): rows {suffixes} "
                     f"(components in the frame of {loop.frame})" + (f", {dropped} dropped (identically zero)"
                                                                     if dropped else ""))
        named.update(loop.rows)
    normalizing = [c.name for c in system.constraints if robot is not None and c.name.endswith(".normalization")]
    if normalizing:
        lines.append("Euler-parameter normalizations (floating and ball joints): " + ", ".join(normalizing))
    others = [c.name for c in system.constraints
              if c.name not in named and not c.name.endswith(".mimic") and c.name not in normalizing]
    if others:
        lines.append(("loop-closing and coupling constraints: " if robot is not None else "other constraints: ")
                     + ", ".join(others))
    elif robot is not None and not system.constraints:
        lines.append("no constraints: a tree")
    lines.append(f"Gruebler count m - r - s = {m - r - s} (the mobility, from the rank of Phi_q at the assembled "
                 "state: kronlag check)")
    return "\n".join(lines)
