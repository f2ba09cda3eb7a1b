"""jaxcal: elastostatic calibration of heavy quasi-serial robots in JAX.

Stiffness model (VJM springs, active parallelogram, spring compensator, gravity, full
static equilibrium), identification with uncertainties, design of experiments,
Monte-Carlo noise studies and a discrepancy workflow. Units are SI inside; files and
command-line output carry their units in their names.

Identification and µm-level simulation need float64:
`jax.config.update("jax_enable_x64", True)` before use (the library never changes
global configuration by itself).
"""

from ._compensator import (
    compensator_force as compensator_force,
)
from ._compensator import (
    compensator_potential as compensator_potential,
)
from ._compensator import (
    compensator_stiffness as compensator_stiffness,
)
from ._compensator import (
    compensator_torque as compensator_torque,
)
from ._compensator import (
    eta_exact as eta_exact,
)
from ._compensator import (
    eta_printed_eq11 as eta_printed_eq11,
)
from ._compensator import (
    spring_length as spring_length,
)
from ._effects import AbstractEffect as AbstractEffect
from ._equilibrium import (
    Equilibrium as Equilibrium,
)
from ._equilibrium import (
    deflection as deflection,
)
from ._equilibrium import (
    equilibrium as equilibrium,
)
from ._equilibrium import (
    solve_deflection as solve_deflection,
)
from ._equilibrium import (
    solve_equilibrium as solve_equilibrium,
)
from ._equilibrium import (
    total_potential as total_potential,
)
from ._io import (
    DataError as DataError,
)
from ._io import (
    Dataset as Dataset,
)
from ._io import (
    read_dataset as read_dataset,
)
from ._io import (
    write_dataset as write_dataset,
)
from ._kinematics import (
    EXTRA_SITES as EXTRA_SITES,
)
from ._kinematics import (
    Pose as Pose,
)
from ._kinematics import (
    forward as forward,
)
from ._kinematics import (
    jacobian_theta as jacobian_theta,
)
from ._kinematics import (
    mass_positions as mass_positions,
)
from ._kinematics import (
    tool_point as tool_point,
)
from ._kinematics import (
    wrist_centre as wrist_centre,
)
from ._linear import (
    cartesian_compliance as cartesian_compliance,
)
from ._linear import (
    cartesian_stiffness as cartesian_stiffness,
)
from ._linear import (
    joint_stiffness as joint_stiffness,
)
from ._linear import (
    linear_deflection as linear_deflection,
)
from ._observation import (
    observation_aggregated as observation_aggregated,
)
from ._observation import (
    observation_linear as observation_linear,
)
from ._observation import (
    observation_physical as observation_physical,
)
from ._observation import (
    q2_groups as q2_groups,
)
from ._parameters import (
    get_parameters as get_parameters,
)
from ._parameters import (
    parameter_names as parameter_names,
)
from ._parameters import (
    parameter_units as parameter_units,
)
from ._parameters import (
    set_parameters as set_parameters,
)
from ._robot import (
    PRESETS as PRESETS,
)
from ._robot import (
    Experiment as Experiment,
)
from ._robot import (
    Robot as Robot,
)
from ._robot import (
    load_robot as load_robot,
)
from ._robot import (
    robot_from_dict as robot_from_dict,
)
from ._robot import (
    robot_to_dict as robot_to_dict,
)
from ._simulate import (
    DeflectionError as DeflectionError,
)
from ._simulate import (
    model_deflections as model_deflections,
)
from ._simulate import (
    simulate as simulate,
)

__version__ = "0.1.0"
