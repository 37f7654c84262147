"""A parameter sweep on a Dask cluster
=====================================

The four-bar's crank driven by a torque ``tau`` from an initial crank speed ``q1d``: a grid of 8 x 8
cases, 1 s each, run by ``kronlag.sweep`` on an existing Dask cluster given by its scheduler's
address.  Here the cluster is a ``LocalCluster`` of two worker processes started apart from the
sweep, as ``dask scheduler`` and ``dask worker tcp://HOST:8786`` would start one across machines
(each worker needs kronlag, and a C compiler or the compiled-library cache); the command line does
the same with ``kronlag sweep four_bar --grid tau=-2:2:8 --grid q1d=0.5:8:8 --scheduler ADDRESS``.
The same sweep in this process gives the same table to the last bit.

Writes ``sweep_on_a_cluster.png``: the crank's turn in 1 s over the grid.  Run:
``python3 examples/sweep_on_a_cluster.py``.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from dask.distributed import LocalCluster

import kronlag
from kronlag.model.builtin import load_example


def main() -> None:
    example = load_example("four_bar", apply_drives=False)
    model = kronlag.derive(example.system).numeric(example.numeric_values())
    torques, speeds = np.linspace(-2.0, 2.0, 8), np.linspace(0.5, 8.0, 8)
    options = dict(parameters={"tau": torques, "q1d": speeds}, initial_states=example.guess_vectors(),
                   fixed=example.fixed, t_span=(0.0, 1.0), t_eval=np.linspace(0.0, 1.0, 51),
                   outcomes={"turn": lambda trajectory: trajectory.q[-1, 0] - trajectory.q[0, 0]}, progress=False)

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        print(f"scheduler at {cluster.scheduler_address}")
        result = kronlag.sweep(model, scheduler=cluster.scheduler_address, **options)

    here = kronlag.sweep(model, workers=0, **options)
    print(f"{len(result.table)} cases, {len(result.failed)} not ok; the same as in this process: "
          f"{result.table.drop(columns='wall_time').equals(here.table.drop(columns='wall_time'))}")

    turn = result.table["turn"].to_numpy().reshape(len(torques), len(speeds))
    figure, axes = plt.subplots(figsize=(6, 4.5))
    image = axes.pcolormesh(speeds, torques, turn, shading="nearest", cmap="viridis")
    figure.colorbar(image, ax=axes, label="crank turn in 1 s [rad]")
    axes.set_xlabel("initial crank speed q1d [rad/s]")
    axes.set_ylabel("crank torque tau [N m]")
    axes.set_title("four-bar sweep on a Dask cluster")
    figure.tight_layout()
    figure.savefig("sweep_on_a_cluster.png", dpi=100)


# The workers are started as new processes that import this script again: the guard keeps them from
# running the sweep themselves.
if __name__ == "__main__":
    main()
