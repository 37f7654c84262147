"""kronlag.sweep (module kronlag.sweeps): many simulations of one built model, serially and on a local Dask cluster."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

import kronlag
from kronlag.model.builtin import load_example
from kronlag.studies.sweeps import grid, sweep

T_EVAL = np.linspace(0.0, 1.0, 21)


@pytest.fixture(scope="module")
def example():
    return load_example("four_bar", apply_drives=False)


@pytest.fixture(scope="module")
def model(example):
    return kronlag.derive(example.system).numeric(example.numeric_values())


def reference_final_angles(example, values: dict) -> np.ndarray:
    """The case simulated by hand: a model built with the case's values, assembled, integrated."""
    parameters = {**example.numeric_values(), **{k: v for k, v in values.items() if k != "q1d"}}
    fresh = kronlag.derive(example.system).numeric(parameters)
    q0, qd0 = fresh.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_guess=[2.0, 0, 0],
                             qd_fixed={"q1": values.get("q1d", 2.0)})
    return kronlag.simulate(fresh, (0.0, 1.0), q0, qd0, t_eval=T_EVAL).q[-1]


def test_serial_sweep_matches_cases_built_and_run_one_by_one(model, example):
    result = sweep(model, parameters={"m2": [1.0, 4.0], "q1d": [1.0, 5.0]}, initial_states=([1.0, 0.5, 1.5], [2.0, 0, 0]),
                   fixed=["q1"], t_span=(0.0, 1.0), workers=0, t_eval=T_EVAL)
    table = result.table
    assert list(table["case"]) == [0, 1, 2, 3] and set(table["status"]) == {"ok"}
    assert list(table.columns[:5]) == ["case", "m2", "q1d", "status", "message"]
    for row, values in zip(table.itertuples(), grid(m2=[1.0, 4.0], q1d=[1.0, 5.0])):
        expected = reference_final_angles(example, values)
        np.testing.assert_allclose([row.q1_final, row.q2_final, row.q3_final], expected, rtol=1e-12)
        assert row.max_position_residual < 1e-9


def test_a_failing_case_is_reported_with_status_and_message_and_the_others_run(model):
    cases = [{"l2": 0.6}, {"l2": 0.05}]  # a 5 cm coupler cannot close the loop
    result = sweep(model, parameters=cases, initial_states=([1.0, 0.5, 1.5], [0.0, 0, 0]), fixed=["q1"],
                   t_span=(0.0, 0.5), workers=0, outcomes={"q1_end": lambda trajectory: trajectory.q[-1, 0]})
    assert list(result.table["status"]) == ["ok", "error"]
    assert "AssemblyError" in result.failed["message"].iloc[0]
    assert np.isnan(result.table["q1_end"].iloc[1]) and np.isfinite(result.table["q1_end"].iloc[0])


def test_unknown_swept_names_are_listed(model):
    with pytest.raises(ValueError, match="unknown swept name.*mass"):
        sweep(model, parameters={"mass": [1.0]}, initial_states=([1.0, 0.5, 1.5], [0.0, 0, 0]), t_span=(0, 1),
              workers=0)


@pytest.mark.slow
def test_local_cluster_loses_nothing_when_a_worker_is_killed_mid_sweep(model):
    distributed = pytest.importorskip("dask.distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = distributed.Client(cluster)
    killed = []

    def kill_a_worker(done: int, total: int) -> None:
        if done >= 3 and not killed:
            _, pid = min(client.run(os.getpid).items())
            os.kill(pid, signal.SIGKILL)  # a worker process of this test's own cluster
            killed.append(pid)

    try:
        cases = grid(m2=np.linspace(1.0, 4.0, 4), q1d=np.linspace(1.0, 6.0, 6))
        initial = ([1.0, 0.5, 1.5], [2.0, 0, 0])
        result = sweep(model, parameters=cases, initial_states=initial, fixed=["q1"], t_span=(0.0, 8.0),
                       client=client, batch_size=1, progress=kill_a_worker, t_eval=np.linspace(0, 8, 41))
        survivors = set(client.run(os.getpid).values())
    finally:
        client.close()
        cluster.close()
    assert killed and killed[0] not in survivors
    assert len(result.table) == 24 and set(result.table["status"]) == {"ok"}, result.failed
    serial = sweep(model, parameters=cases, initial_states=initial, fixed=["q1"], t_span=(0.0, 8.0), workers=0,
                   t_eval=np.linspace(0, 8, 41))
    np.testing.assert_allclose(result.table[["q1_final", "q2_final", "q3_final"]].to_numpy(),
                               serial.table[["q1_final", "q2_final", "q3_final"]].to_numpy(), rtol=1e-12)


def test_cli_sweep_writes_the_table_and_fails_on_failed_cases(tmp_path, capsys):
    from kronlag.app.cli import main

    table = tmp_path / "sweep.csv"
    assert main(["sweep", "four_bar", "--grid", "m3=2:4:3", "--t-end", "0.5", "--points", "11", "--workers", "0",
                 "--output", str(table)]) == 0
    import pandas as pd

    frame = pd.read_csv(table)
    assert list(frame["m3 [kg]"]) == [2.0, 3.0, 4.0] and set(frame["status"]) == {"ok"}
    assert main(["sweep", "four_bar", "--grid", "l2=0.6,0.05", "--t-end", "0.5", "--workers", "0"]) == 1
    assert "case 1: error: AssemblyError" in capsys.readouterr().err
    assert main(["sweep", "four_bar", "--grid", "m3=2:4"]) == 2


def test_kept_trajectories_become_an_xarray_dataset(model):
    pytest.importorskip("xarray")
    result = sweep(model, parameters={"q1d": [1.0, 3.0]}, initial_states=([1.0, 0.5, 1.5], [0.0, 0, 0]),
                   fixed=["q1"], t_span=(0.0, 1.0), workers=0, t_eval=T_EVAL, keep_trajectories=True)
    dataset = result.to_xarray()
    assert dataset["q"].shape == (2, len(T_EVAL), 3)
    assert list(dataset["coordinate"].values) == ["q1", "q2", "q3"]
    np.testing.assert_allclose(dataset["q"].sel(case=1).values, result.trajectories[1].q)
    np.testing.assert_allclose(dataset["qd"].sel(case=0, coordinate="q1").values[0], 1.0)
    assert list(dataset["q1d"].values) == [1.0, 3.0]


def test_a_factory_builds_the_model_of_each_case(example):
    """A factory may change what with_parameters cannot: here the model file's derived inertia I3 = m3 l3^2 / 12."""
    equations = kronlag.derive(example.system)

    def factory(case):
        values = {**example.numeric_values(), **case, "I3": case["m3"] * 0.5 ** 2 / 12}
        return equations.numeric(values)

    result = sweep(factory, parameters={"m3": [2.0, 5.0]}, initial_states=([1.0, 0.5, 1.5], [2.0, 0, 0]),
                   fixed=["q1"], qd_fixed=["q1"], t_span=(0.0, 1.0), workers=0, t_eval=T_EVAL)
    assert set(result.table["status"]) == {"ok"}
    for row in result.table.itertuples():
        fresh = factory({"m3": row.m3})
        q0, qd0 = fresh.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_guess=[2.0, 0, 0], qd_fixed={"q1": 2.0})
        expected = kronlag.simulate(fresh, (0.0, 1.0), q0, qd0, t_eval=T_EVAL).q[-1]
        np.testing.assert_allclose([row.q1_final, row.q2_final, row.q3_final], expected, rtol=1e-12)
