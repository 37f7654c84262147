"""Labelled array results: ``to_xarray()`` of a trajectory, an inverse-dynamics run and a sweep, with
their labels (coordinates, constraints, joints) and units, and the multipliers' column names."""

import sys

import numpy as np
import pytest

import kronlag
from kronlag.app.workflows import model_units, simulate_model
from kronlag.model.builtin import load_example

xr = pytest.importorskip("xarray")

TIMES = np.linspace(0.0, 0.1, 6)


@pytest.fixture(scope="module")
def engine():
    return load_example("slider_crank_engine", apply_drives=False)


@pytest.fixture(scope="module")
def engine_run(engine):
    trajectory = simulate_model(engine, t_end=0.1, t_eval=TIMES)
    assert trajectory.success, trajectory.message
    return trajectory


def test_a_trajectory_is_labelled_by_coordinate_constraint_and_joint(engine, engine_run):
    dataset = engine_run.to_xarray(units=model_units(engine))
    system = engine.system
    assert list(dataset["coordinate"].values) == [q.name for q in system.coordinates]
    assert list(dataset["constraint"].values) == [c.name for c in system.constraints]
    assert list(dataset["joint"].values) == ["main_bearing", "crank_pin", "wrist_pin", "cylinder"]
    assert list(dataset["axis"].values) == ["x", "y"] and list(dataset["couple_axis"].values) == ["z"]
    assert "nonholonomic" not in dataset.dims and "mu" not in dataset  # none in this model, as in the columns
    np.testing.assert_array_equal(dataset["time"].values, TIMES)
    row = [c.name for c in system.constraints].index("wrist_pin.y")
    np.testing.assert_array_equal(dataset["lambda"].sel(constraint="wrist_pin.y").values, engine_run.lam[:, row])
    np.testing.assert_array_equal(dataset["q"].sel(coordinate="theta_rod").values,
                                  engine_run.q[:, engine_run.coordinate_names.index("theta_rod")])
    np.testing.assert_array_equal(dataset["reaction_force"].sel(joint="wrist_pin", axis="y").values,
                                  engine_run.reaction("wrist_pin").force[:, 1])
    np.testing.assert_array_equal(dataset["reaction_couple"].sel(joint="cylinder").values[:, 0],
                                  engine_run.columns()["cylinder.Mz"])
    np.testing.assert_array_equal(dataset["potential_energy"].values, engine_run.potential_energy)
    assert dataset.attrs["status"] == 0 and dataset.attrs["result"] == "SUCCESS"
    assert dataset.attrs["method"] == engine_run.method and dataset.attrs["system"] == "slider_crank_engine"


def test_units_travel_as_attributes(engine, engine_run):
    dataset = engine_run.to_xarray(units=model_units(engine))
    assert dataset["time"].attrs["units"] == "s"
    assert dataset["kinetic_energy"].attrs["units"] == "J"
    assert dataset["reaction_force"].attrs["units"] == "N" and dataset["reaction_couple"].attrs["units"] == "N*m"
    # an angle and a length: a unit per coordinate, not one for the variable
    assert "units" not in dataset["q"].attrs
    assert dataset["q_units"].sel(coordinate="theta_crank").item() == "rad"
    assert dataset["q_units"].sel(coordinate="x_piston").item() == "m"
    assert dataset["qd_units"].sel(coordinate="x_piston").item() == "m/s"
    assert dataset["qdd_units"].sel(coordinate="theta_rod").item() == "rad/s^2"
    # a revolute joint's rows carry a force, the prismatic joint's angle row a couple
    assert dataset["lambda_units"].sel(constraint="main_bearing.x").item() == "N"
    assert dataset["lambda_units"].sel(constraint="cylinder.angle").item() == "N*m"
    bare = engine_run.to_xarray()  # no units given: none claimed
    assert all("units" not in variable.attrs for variable in bare.variables.values())
    assert "q_units" not in bare.coords


def test_the_dataset_survives_a_netcdf_file(engine, engine_run, tmp_path):
    pytest.importorskip("scipy")
    dataset = engine_run.to_xarray(units=model_units(engine))
    dataset.to_netcdf(tmp_path / "run.nc", engine="scipy")
    with xr.open_dataset(tmp_path / "run.nc", engine="scipy") as back:
        np.testing.assert_array_equal(back["lambda"].sel(constraint="crank_pin.x").values,
                                      dataset["lambda"].sel(constraint="crank_pin.x").values)
        assert back["reaction_force"].attrs["units"] == "N" and back.attrs["message"] == engine_run.message


def test_the_columns_name_the_multipliers_by_constraint(engine_run):
    columns = engine_run.columns()
    multipliers = [name for name in columns if name.startswith(("lambda", "mu"))]
    assert multipliers == [f"lambda[{c.name}]" for c in engine_run.model.equations.system.constraints]
    np.testing.assert_array_equal(columns["lambda[cylinder.angle]"], engine_run.lam[:, 7])


def test_a_nonholonomic_model_has_mu_by_constraint():
    sleigh = load_example("chaplygin_sleigh", apply_drives=False)
    trajectory = simulate_model(sleigh, t_end=0.05, t_eval=np.linspace(0.0, 0.05, 3))
    names = [c.name for c in sleigh.system.nonholonomic_constraints]
    dataset = trajectory.to_xarray()
    assert list(dataset["nonholonomic"].values) == names
    np.testing.assert_array_equal(dataset["mu"].values, trajectory.mu)
    np.testing.assert_array_equal(dataset["nonholonomic_residual"].values,
                                  trajectory.velocity_residual[:, trajectory.lam.shape[1]:])
    assert [f"mu[{name}]" for name in names] == [n for n in trajectory.columns() if n.startswith("mu[")]


def test_inverse_dynamics_by_actuated_coordinate_and_drive(engine):
    driven = load_example("slider_crank_engine", apply_drives=False)
    driven.system.add_drive("theta_crank", 20 * kronlag.t)
    model = kronlag.derive(driven.system).numeric(driven.numeric_values())
    units = model_units(engine)
    times = np.linspace(0.0, 0.1, 3)
    run = kronlag.inverse_dynamics(model, times, driven.guess_vectors()[0], actuated=["theta_crank"])
    dataset = run.to_xarray(units=units)
    assert list(dataset["actuated"].values) == ["theta_crank"]
    np.testing.assert_array_equal(dataset["force"].sel(actuated="theta_crank").values, run.forces[:, 0])
    assert dataset["force"].attrs["units"] == "N*m"  # a torque on an angle
    np.testing.assert_array_equal(dataset["reaction_force"].sel(joint="main_bearing", axis="x").values,
                                  run.reactions["main_bearing.Fx"])
    assert list(dataset["point"].values) == list(run.points)
    np.testing.assert_array_equal(dataset["point_position"].sel(point="wrist", axis="x").values,
                                  run.points["wrist"]["position"][:, 0])
    assert dataset.attrs["success"] == 1
    own = kronlag.inverse_dynamics(model, times, driven.guess_vectors()[0])  # the drive's own force
    by_drive = own.to_xarray(units=units)
    assert list(by_drive["actuated"].values) == ["drive theta_crank"]
    assert by_drive["force"].attrs["units"] == "N*m"
    assert by_drive["lambda_units"].sel(constraint="drive theta_crank").item() == "N*m"
    assert "lambda[drive theta_crank]" in own.columns()


def test_sweep_dataset_has_units(engine):
    four_bar = load_example("four_bar", apply_drives=False)
    model = kronlag.derive(four_bar.system).numeric(four_bar.numeric_values())
    result = kronlag.sweep(model, parameters={"tau": [0.0, 1.0], "q1d": [2.0]}, initial_states=four_bar.guess_vectors(),
                           fixed=four_bar.fixed, t_span=(0.0, 0.1), t_eval=np.linspace(0.0, 0.1, 3), workers=0,
                           progress=False, keep_trajectories=True)
    dataset = result.to_xarray(units=model_units(four_bar, parameters=True))
    assert dataset["tau"].attrs["units"] == "N*m" and dataset["q1d"].attrs["units"] == "rad/s"
    assert dataset["q"].attrs["units"] == "rad" and dataset["qd"].attrs["units"] == "rad/s"
    assert dataset["q2_final"].attrs["units"] == "rad" and dataset["energy_drift"].attrs["units"] == "J"
    assert dataset["time"].attrs["units"] == "s" and dataset["wall_time"].attrs["units"] == "s"
    assert dataset["q"].dims == ("case", "time", "coordinate")
    np.testing.assert_array_equal(dataset["q"].sel(case=1).values, result.trajectories[1].q)


def test_a_missing_xarray_is_named(engine_run, monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match=r"needs xarray: pip install xarray \(or 'kronlag\[xarray\]'\)"):
        engine_run.to_xarray()


def test_the_command_line_writes_netcdf_with_the_files_units(tmp_path):
    from kronlag.app.cli import main

    path = tmp_path / "run.nc"
    assert main(["simulate", "slider_crank_engine", "--t-end", "0.02", "--points", "5", "--output", str(path)]) == 0
    with xr.open_dataset(path) as data:
        assert data.sizes["time"] == 5 and data["time"].attrs["units"] == "s"
        assert data["q_units"].sel(coordinate="theta_crank").item() == "rad"
        assert data["reaction_force"].attrs["units"] == "N" and data.attrs["status"] == 0
    inverse = tmp_path / "inverse.nc"
    assert main(["inverse", "four_bar", "--drive", "q1=2*t", "--t-end", "0.1", "--output", str(inverse)]) == 0
    with xr.open_dataset(inverse) as data:
        assert data["actuated"].values.tolist() == ["q1"] and data["force"].attrs["units"] == "N*m"
