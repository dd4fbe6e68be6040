"""The car: its true parameters, its force laws and its equations of motion.

* `racing_lib.vehicle.params`: `VehicleParams`, every parameter of the simulated car, documented
  once (the paper's table for the Mazda Demio XD Touring '15 plus what the paper does not give).
* `racing_lib.vehicle.forces`: the force laws (tyres, drag, loads, engine), written once for floats,
  NumPy arrays and CasADi symbols.
* `racing_lib.vehicle.dynamics`: the double-track vector field the simulated car integrates and the
  best-lap planner optimizes with.

The names below are re-exported, so ``from racing_lib.vehicle import VehicleParams`` works.
"""

from racing_lib.vehicle.forces import (
    CASADI_OPS,
    MATH_OPS,
    NUMPY_OPS,
    MathOps,
    Numeric,
    axle_cornering_stiffness,
    drag_force,
    drive_force,
    drive_force_envelope,
    engine_torque,
    engine_torque_ops,
    gear_rpm,
    lateral_load_transfer,
    longitudinal_load_transfer,
    ops_for,
    pacejka_lateral,
    rolling_resistance,
    slip_angles,
    static_axle_loads,
    wheel_loads,
)
from racing_lib.vehicle.params import G, VehicleParams

__all__ = [
    "CASADI_OPS",
    "G",
    "MATH_OPS",
    "NUMPY_OPS",
    "MathOps",
    "Numeric",
    "VehicleParams",
    "axle_cornering_stiffness",
    "drag_force",
    "drive_force",
    "drive_force_envelope",
    "engine_torque",
    "engine_torque_ops",
    "gear_rpm",
    "lateral_load_transfer",
    "longitudinal_load_transfer",
    "ops_for",
    "pacejka_lateral",
    "rolling_resistance",
    "slip_angles",
    "static_axle_loads",
    "wheel_loads",
]
