"""jaxcal: elastostatic calibration of heavy quasi-serial robots in JAX.

Stiffness model (VJM springs, active parallelogram, spring compensator, gravity, full
static equilibrium), identification with uncertainties, design of experiments,
Monte-Carlo noise studies and a discrepancy workflow. Units are SI inside; files and
command-line output carry their units in their names.

Identification and µm-level simulation need float64:
`jax.config.update("jax_enable_x64", True)` before use (the library never changes
global configuration by itself).
"""

from ._candidates import Backlash as Backlash
from ._candidates import Candidate as Candidate
from ._candidates import CompensatorSpring as CompensatorSpring
from ._candidates import JointNonlinearity as JointNonlinearity
from ._candidates import LinkBending as LinkBending
from ._candidates import ToolCompliance as ToolCompliance
from ._candidates import TrackerRotation as TrackerRotation
from ._candidates import default_candidates as default_candidates
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
from ._constraints import (
    constraint_values as constraint_values,
)
from ._constraints import design_bounds as design_bounds
from ._constraints import design_loads as design_loads
from ._criteria import DesignCriteria as DesignCriteria
from ._criteria import design_criteria as design_criteria
from ._criteria import design_observation as design_observation
from ._design import Design as Design
from ._design import DesignProblem as DesignProblem
from ._design import design_objective as design_objective
from ._design import optimise_design as optimise_design
from ._discrepancy import CandidateResult as CandidateResult
from ._discrepancy import DiscoveryReport as DiscoveryReport
from ._discrepancy import discover as discover
from ._discrepancy import discover_batch as discover_batch
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
from ._identification import (
    IdentificationResult as IdentificationResult,
)
from ._identification import (
    fit_linear as fit_linear,
)
from ._identification import (
    fit_nonlinear as fit_nonlinear,
)
from ._identification import (
    linear_system as linear_system,
)
from ._identification import (
    solve_linear as solve_linear,
)
from ._identify import (
    identify as identify,
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
from ._lsq import (
    LsqFit as LsqFit,
)
from ._lsq import (
    nonlinear_fit as nonlinear_fit,
)
from ._mc_plots import plot_error_vs_noise as plot_error_vs_noise
from ._mc_plots import plot_histograms as plot_histograms
from ._mc_stats import MonteCarloResult as MonteCarloResult
from ._mc_sweeps import load_sweep as load_sweep
from ._mc_sweeps import noise_sweep as noise_sweep
from ._montecarlo import monte_carlo as monte_carlo
from ._montecarlo import trial_noise as trial_noise
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
from ._plans import feasible_q3_range as feasible_q3_range
from ._plans import paper_table5_plan as paper_table5_plan
from ._plans import random_designs as random_designs
from ._plans import structured_design as structured_design
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
from ._supermodel import SuperModel as SuperModel
from ._two_step import (
    fit_two_step as fit_two_step,
)
from ._two_step import (
    solve_two_step as solve_two_step,
)
from ._two_step import (
    two_step_system as two_step_system,
)

__version__ = "0.1.0"
