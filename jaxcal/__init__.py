"""jaxcal: elastostatic calibration of heavy quasi-serial robots in JAX.

Stiffness model (VJM springs, active parallelogram, spring compensator, gravity, full
static equilibrium), identification with uncertainties, design of experiments,
Monte-Carlo noise studies and a discrepancy workflow. Units are SI inside; files and
command-line output carry their units in their names.

Identification and µm-level simulation need float64:
`jax.config.update("jax_enable_x64", True)` before use (the library never changes
global configuration by itself).
"""

from ._cache import (
    cache_dir as cache_dir,
    disable_compilation_cache as disable_compilation_cache,
    enable_compilation_cache as enable_compilation_cache,
)
from ._calibration import (
    Calibration as Calibration,
    calibrated_robot as calibrated_robot,
    read_calibration as read_calibration,
    save_robot as save_robot,
)
from ._candidates import (
    Backlash as Backlash,
    Candidate as Candidate,
    CompensatorSpring as CompensatorSpring,
    JointNonlinearity as JointNonlinearity,
    LinkBending as LinkBending,
    ToolCompliance as ToolCompliance,
    TrackerRotation as TrackerRotation,
    default_candidates as default_candidates,
)
from ._compensator import (
    compensator_force as compensator_force,
    compensator_potential as compensator_potential,
    compensator_stiffness as compensator_stiffness,
    compensator_torque as compensator_torque,
    eta_exact as eta_exact,
    eta_printed_eq11 as eta_printed_eq11,
    spring_length as spring_length,
)
from ._constraints import (
    CONSTRAINTS as CONSTRAINTS,
    constraint_values as constraint_values,
    design_bounds as design_bounds,
    design_loads as design_loads,
)
from ._criteria import (
    DesignCriteria as DesignCriteria,
    design_criteria as design_criteria,
    design_observation as design_observation,
)
from ._design import (
    Design as Design,
    DesignProblem as DesignProblem,
    design_objective as design_objective,
    optimise_design as optimise_design,
    rank_random_designs as rank_random_designs,
)
from ._design_bound import (
    DesignBound as DesignBound,
    design_bound as design_bound,
)
from ._discrepancy import (
    CandidateResult as CandidateResult,
    DiscoveryReport as DiscoveryReport,
    discover as discover,
    discover_batch as discover_batch,
)
from ._effects import AbstractEffect as AbstractEffect
from ._equilibrium import (
    Equilibrium as Equilibrium,
    deflection as deflection,
    equilibrium as equilibrium,
    solve_deflection as solve_deflection,
    solve_equilibrium as solve_equilibrium,
    total_potential as total_potential,
)
from ._identification import (
    IdentificationResult as IdentificationResult,
    fit_linear as fit_linear,
    fit_nonlinear as fit_nonlinear,
    linear_system as linear_system,
    solve_linear as solve_linear,
)
from ._identify import (
    identify as identify,
)
from ._io import (
    DataError as DataError,
    Dataset as Dataset,
    read_dataset as read_dataset,
    write_dataset as write_dataset,
)
from ._kinematics import (
    EXTRA_SITES as EXTRA_SITES,
    Pose as Pose,
    forward as forward,
    jacobian_theta as jacobian_theta,
    mass_positions as mass_positions,
    tool_point as tool_point,
    wrist_centre as wrist_centre,
)
from ._linear import (
    cartesian_compliance as cartesian_compliance,
    cartesian_stiffness as cartesian_stiffness,
    joint_stiffness as joint_stiffness,
    linear_deflection as linear_deflection,
)
from ._lsq import (
    LsqFit as LsqFit,
    nonlinear_fit as nonlinear_fit,
)
from ._mc_plots import (
    plot_error_vs_noise as plot_error_vs_noise,
    plot_histograms as plot_histograms,
)
from ._mc_stats import MonteCarloResult as MonteCarloResult
from ._mc_sweeps import load_sweep as load_sweep, noise_sweep as noise_sweep
from ._montecarlo import monte_carlo as monte_carlo, trial_noise as trial_noise
from ._observation import (
    observation_aggregated as observation_aggregated,
    observation_linear as observation_linear,
    observation_physical as observation_physical,
    q2_groups as q2_groups,
)
from ._parameters import (
    get_parameters as get_parameters,
    parameter_names as parameter_names,
    parameter_units as parameter_units,
    set_parameters as set_parameters,
)
from ._plans import (
    PAPER_TABLE5_DEG as PAPER_TABLE5_DEG,
    feasible_q3_range as feasible_q3_range,
    jaxcal_to_paper as jaxcal_to_paper,
    paper_q2 as paper_q2,
    paper_table5_plan as paper_table5_plan,
    paper_to_jaxcal as paper_to_jaxcal,
    random_designs as random_designs,
    structured_design as structured_design,
)
from ._robot import (
    PRESETS as PRESETS,
    Experiment as Experiment,
    Robot as Robot,
    load_robot as load_robot,
    robot_from_dict as robot_from_dict,
    robot_to_dict as robot_to_dict,
)
from ._simulate import (
    DeflectionError as DeflectionError,
    model_deflections as model_deflections,
    simulate as simulate,
)
from ._solution import RESULTS as RESULTS
from ._supermodel import SuperModel as SuperModel
from ._two_step import (
    fit_two_step as fit_two_step,
    solve_two_step as solve_two_step,
    two_step_system as two_step_system,
)
from .compensation import (
    Compensation as Compensation,
    compensate as compensate,
    read_path as read_path,
)

__version__ = "0.1.0"
