"""Cassie's leg loops from its SDF file: the named loop reactions, plotted (docs/sdf.md).

example-robot-data's ``cassie_v2.sdf`` is read by :func:`kronlag.load_sdf` with its pelvis bolted to
the world (a ``fixed`` joint from ``world`` to ``pelvis`` added to the file's text, SDFormat's way of
fixing a model) and, for the figure, the right leg's links and joints taken out: Cassie's left leg
on a stand.  The five joints the file names ``-op`` (its motors) are held at the file's pose by
drives (their multipliers are the motor torques), and the knee and heel leaf springs act with the
file's ``<spring_stiffness>`` (the reader keeps joint springs out of the dynamics, so they are added
here as potentials): the leg has one free mode, its springs.  An upward force on the foot grows from
0 to 300 N (the ground pushing the leg of a robot standing on it); at each value the leg is found at
rest on its springs, and the loops' multipliers, named by the reader after the loop-closing joints
(``left-pitch-rod-joint.x`` ...: the force on the joint's parent link, the Achilles or plantar rod,
in newtons, components in the frame of the loop's nearest common ancestor link), are plotted.

With both legs (``cassie_on_stand(path)``), the right foot's loop, planar only to about 7e-8 rad in
the file, has an out-of-plane row ``right-plantar-foot-joint.z`` that depends on the others
(``kronlag check`` lists it): it is dropped, as the reader drops the left foot's identically zero
one, so that every multiplier is unique.

Run: ``python docs/figures/cassie_loop_reactions.py [out.png]`` (needs example-robot-data; about
30 s with an empty ``KRONLAG_CACHE`` - load 5 s, derive 5 s, C build 21 s, 20 s of CPU in all -
10 s once the build is cached; the 41 rests take 0.2 s).  It writes ``docs/images/cassie_loop_reactions.png``
by default.
"""

from __future__ import annotations

import importlib.metadata
import resource
import sys
import tempfile
import time
import warnings
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

import kronlag

#: Where example-robot-data installs Cassie's SDF file, inside its distribution.
CASSIE = "cmeel.prefix/share/example-robot-data/robots/cassie_description/robots/cassie_v2.sdf"
#: The joints the file names ``-op``, per leg: the motors, held at the file's pose.
MOTORS = ("roll-op", "yaw-op", "pitch-op", "knee-op", "foot-op")
#: The leaf springs of the file (``<spring_stiffness>``, N m/rad, ``<spring_reference>`` 0), per leg.
SPRINGS = {"knee-shin-joint": 1500.0, "tarsus-spring-joint": 1250.0}
#: The loops, per leg: the joints that close them (the Achilles rod at the hip, the plantar rod at the foot).
LOOPS = {"pitch-rod-joint": "Achilles rod", "plantar-foot-joint": "plantar rod"}
#: The row of the right foot's loop that depends on the others (planar to ~7e-8 rad).
DEPENDENT_ROW = "right-plantar-foot-joint.z"
#: SDFormat's fixed joint from the world: the pelvis on a stand.
STAND = '<joint name="stand" type="fixed"><parent>world</parent><child>pelvis</child></joint>\n'
#: N: the ground's push on the foot at the end of the figure (Cassie, ~33 kg, standing on one leg).
FOOT_LOAD = 300.0
SIDES = ("left", "right")
#: The leg the figure shows (the other is its mirror image, and one leg halves the build).
FIGURE_LEGS = ("left",)


def cassie_file() -> Path | None:
    """The path of example-robot-data's ``cassie_v2.sdf``, or ``None`` if it is not installed."""
    try:
        path = Path(str(importlib.metadata.distribution("example-robot-data").locate_file(CASSIE)))
    except importlib.metadata.PackageNotFoundError:
        return None
    return path if path.is_file() else None


def cassie_on_stand(path: Path, *, legs: tuple[str, ...] = SIDES, foot_load: float = 0.0) -> kronlag.System:
    """Cassie from ``path`` with its pelvis fixed to the world and only the ``legs`` named (the other
    leg's links and joints taken out of the file's text), its motors held by drives (named after the
    joints) and its leaf springs as potentials (named ``"<joint> spring"``); the dependent row of the
    right foot's loop removed.  ``foot_load`` (N/s): an upward force ``foot_load * t`` on each foot's
    centre of mass (named ``"<leg> ground force"``), as the ground pushes a leg that stands on it."""
    document = ElementTree.fromstring(path.read_text())  # example-robot-data's file, not user input
    model = document.find("model")
    for element in list(model):
        if element.tag in ("link", "joint") and element.get("name", "").split("-")[0] in set(SIDES) - set(legs):
            model.remove(element)
    model.append(ElementTree.fromstring(STAND))
    with tempfile.TemporaryDirectory() as folder:
        on_stand = Path(folder) / path.name
        on_stand.write_text(ElementTree.tostring(document, encoding="unicode"))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", kronlag.model.robot_formats.RobotFileWarning)  # meshes, skipped tags
            system = kronlag.load_sdf(on_stand)
    coordinates = {joint.name: joint.coordinate for joint in system.robot.joints}
    by_name = {q.name: q for q in system.coordinates}
    for side in legs:
        for motor in MOTORS:
            system.add_drive(coordinates[f"{side}-{motor}"], 0, name=f"{side}-{motor}")
        for spring, stiffness in SPRINGS.items():
            angle = by_name[coordinates[f"{side}-{spring}"]]
            system.add_potential(stiffness * angle ** 2 / 2, name=f"{side}-{spring} spring")
        if foot_load:
            system.add_force(system.body(f"{side}-foot").position, (0, 0, foot_load * kronlag.t),
                             name=f"{side} ground force")
    system.constraints[:] = [row for row in system.constraints if row.name != DEPENDENT_ROW]
    return system


def legs_of(system: kronlag.System) -> list[str]:
    """The legs of ``system`` (of :data:`SIDES`)."""
    return [side for side in SIDES if any(joint.name.startswith(f"{side}-") for joint in system.robot.joints)]


def loop_rows(system: kronlag.System) -> dict[str, list[str]]:
    """The multipliers' names of each loop-closing joint (``"left-pitch-rod-joint"``: ``[".x", ...]``
    in full), in the order of :data:`SIDES` and :data:`LOOPS`."""
    names = [row.name for row in system.constraints]
    return {f"{side}-{loop}": [name for name in names if name.startswith(f"{side}-{loop}.")]
            for side in legs_of(system) for loop in LOOPS}


def static_equilibrium(model: kronlag.NumericModel, system: kronlag.System, *, t: float = 0.0, guess=None,
                       tol: float = 1e-10, max_iterations: int = 30) -> tuple[np.ndarray, kronlag.ForwardDynamicsResult]:
    """The legs at rest on their springs at time ``t`` (the loads then): ``(q, forward dynamics at
    (q, 0, t))`` with every acceleration below ``tol``, found from ``guess`` (default the file's pose).
    Each leg has one free mode (motors held); the knee springs' angles are found by the secant method
    on their accelerations at rest, the other coordinates assembled around them."""
    springs = [next(joint.coordinate for joint in system.robot.joints if joint.name == f"{side}-knee-shin-joint")
               for side in legs_of(system)]
    index = [[x.name for x in system.coordinates].index(name) for name in springs]
    guess = np.zeros(model.m) if guess is None else np.asarray(guess, dtype=float)
    at_rest = np.zeros(model.m)

    def accelerations(angles: np.ndarray) -> tuple[np.ndarray, kronlag.ForwardDynamicsResult]:
        q, _ = model.assemble(guess, fixed=dict(zip(springs, angles)), t=t)
        return q, model.forward_dynamics(q, at_rest, t)

    previous = guess[index]
    q, result = accelerations(previous)
    angles = previous - 0.01  # rad: a first step, the way the legs sag
    for _ in range(max_iterations):
        last = result.qdd[index]
        guess = q
        q, result = accelerations(angles)
        if np.max(np.abs(result.qdd)) < tol:
            return q, result
        # the legs are independent (the pelvis is held): a secant step for each
        previous, angles = angles, angles - result.qdd[index] * (angles - previous) / (result.qdd[index] - last)
    raise kronlag.EquilibriumError(f"Cassie's legs found no rest on their springs in {max_iterations} steps: "
                                   f"max |qdd| = {np.max(np.abs(result.qdd)):.3g}", float(np.max(np.abs(result.qdd))))


def plot(x: np.ndarray, multipliers: dict[str, np.ndarray], system: kronlag.System, path: Path, *, xlabel: str,
         title: str) -> None:
    """A panel per loop (rows: the Achilles and plantar rods, columns: the legs): each named multiplier
    (``multipliers[name]`` over ``x``) and the force's magnitude."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = {loop.joint: loop.frame for loop in system.robot.loops}
    legs = legs_of(system)
    figure, grid = plt.subplots(len(LOOPS), len(legs), figsize=(3 + 6 * len(legs), 7.5), sharex=True, squeeze=False,
                                layout="constrained")
    for (joint, rows), axes in zip(loop_rows(system).items(), grid.T.ravel()):
        values = np.column_stack([multipliers[row] for row in rows])
        for row, column in zip(rows, values.T):
            axes.plot(x, column, label=row)
        axes.plot(x, np.linalg.norm(values, axis=1), "k--", label="|F|")
        side, loop = joint.split("-", 1)
        axes.set_title(f"{joint}: force on the {side} {LOOPS[loop]}, {frames[joint]} frame", fontsize=10)
        axes.set_ylabel("force [N]")
        axes.grid(alpha=0.3)
        axes.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    for axes in grid[-1]:
        axes.set_xlabel(xlabel)
    figure.suptitle(title)
    figure.savefig(path, dpi=110)
    plt.close(figure)


def cpu_seconds() -> float:
    """CPU time of this process and of the compilers it ran (the machine's load does not count)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def press(out: Path, *, legs: tuple[str, ...] = FIGURE_LEGS) -> dict[str, np.ndarray]:
    """The figure of the page: the leg at rest on its springs, motors held, while a vertical force on
    the foot grows from 0 to :data:`FOOT_LOAD` (:func:`static_equilibrium` at each value: the ground
    pushing the leg of a robot that stands on it); the loops' multipliers by name against the force.
    Prints the times and returns the multipliers."""
    path = cassie_file()
    if path is None:
        sys.exit("example-robot-data is not installed (pip install example-robot-data)")
    times = [(time.perf_counter(), cpu_seconds())]
    system = cassie_on_stand(path, legs=legs, foot_load=FOOT_LOAD)  # the full load at t = 1
    times.append((time.perf_counter(), cpu_seconds()))
    equations = kronlag.derive(system)
    times.append((time.perf_counter(), cpu_seconds()))
    model = equations.numeric(system.robot.values)
    times.append((time.perf_counter(), cpu_seconds()))
    instants, q, rows = np.linspace(0, 1, 41), np.zeros(model.m), []
    for instant in instants:
        q, rest = static_equilibrium(model, system, t=instant, guess=q, tol=1e-6)  # rad/s^2: at rest
        rows.append(rest.lam)
    times.append((time.perf_counter(), cpu_seconds()))
    print(", ".join(f"{step} {end[0] - start[0]:.1f} s (CPU {end[1] - start[1]:.1f} s)" for step, start, end in
                    zip(("load", "derive", f"build ({model.backend})", f"{len(instants)} rests"), times, times[1:])))
    springs = {joint.name: q[[x.name for x in system.coordinates].index(joint.coordinate)] for joint in system.robot.joints
               if joint.name.partition("-")[2] in SPRINGS}
    print("spring deflections at the full load: " + ", ".join(f"{name} {np.degrees(angle):.2f} deg"
                                                              for name, angle in springs.items()))
    multipliers = dict(zip(model.constraint_names, np.array(rows).T))
    report(system, multipliers)
    plot(FOOT_LOAD * instants, multipliers, system, out, xlabel="upward force on the foot [N]",
         title=f"Cassie (cassie_v2.sdf) on a stand, motors held: its {' and '.join(legs)} leg pushed up at the foot,\n"
               "at rest on the file's leaf springs; the loop reactions, named after the loop-closing joints")
    print(f"wrote {out}")
    return multipliers


def report(system: kronlag.System, multipliers: dict[str, np.ndarray]) -> None:
    """Print each loop's force range."""
    for joint, rows in loop_rows(system).items():
        magnitude = np.linalg.norm(np.column_stack([multipliers[row] for row in rows]), axis=1)
        print(f"{joint:>24}: |F| from {magnitude[0]:6.1f} N to {magnitude[-1]:6.1f} N "
              f"(min {magnitude.min():6.1f}, max {magnitude.max():6.1f})")


if __name__ == "__main__":
    press(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parents[1] / "images" / "cassie_loop_reactions.png")
