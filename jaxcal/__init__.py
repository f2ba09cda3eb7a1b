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
from ._format import format_table as format_table
from ._identification.calibration import (
    Calibration as Calibration,
    calibrated_robot as calibrated_robot,
    read_calibration as read_calibration,
    save_robot as save_robot,
)
from ._identification.elastogeometric import calibrate_tree as calibrate_tree
from ._identification.identify import (
    identify as identify,
)
from ._identification.lsq import (
    LsqFit as LsqFit,
    nonlinear_fit as nonlinear_fit,
)
from ._identification.measurement_kinds import (
    KindComparison as KindComparison,
    compare_measurement_kinds as compare_measurement_kinds,
)
from ._identification.method import (
    AbstractMethod as AbstractMethod,
    LinearMethod as LinearMethod,
    NonlinearMethod as NonlinearMethod,
    NonlinearState as NonlinearState,
    TwoStepMethod as TwoStepMethod,
    fit_linear as fit_linear,
    fit_nonlinear as fit_nonlinear,
    fit_two_step as fit_two_step,
)
from ._identification.methods import (
    LinearSystem as LinearSystem,
    linear_system as linear_system,
    solve_linear as solve_linear,
)
from ._identification.parameter_groups import (
    DEFLECTION_GROUPS as DEFLECTION_GROUPS,
    PARAMETER_GROUPS as PARAMETER_GROUPS,
    Parameter as Parameter,
    default_groups as default_groups,
    parameter_table as parameter_table,
)
from ._identification.result import IdentificationResult as IdentificationResult
from ._identification.tree_covariance import saved_covariance as saved_covariance
from ._identification.tree_result import (
    GrossError as GrossError,
    TreeCalibration as TreeCalibration,
)
from ._identification.tree_validation import (
    HeldOut as HeldOut,
    Stage as Stage,
    held_out as held_out,
    marker_errors as marker_errors,
    predicted_markers as predicted_markers,
    validate_tree as validate_tree,
)
from ._identification.two_step import (
    TwoStepSystem as TwoStepSystem,
    solve_two_step as solve_two_step,
    two_step_system as two_step_system,
)
from ._io import (
    DataError as DataError,
    Dataset as Dataset,
    configurations as configurations,
    q2_groups as q2_groups,
    read_dataset as read_dataset,
    write_dataset as write_dataset,
)
from ._markers import (
    MarkerData as MarkerData,
    read_markers as read_markers,
    write_markers as write_markers,
)
from ._model.candidates import (
    Backlash as Backlash,
    Candidate as Candidate,
    CompensatorSpring as CompensatorSpring,
    JointNonlinearity as JointNonlinearity,
    LinkBending as LinkBending,
    ToolCompliance as ToolCompliance,
    TrackerRotation as TrackerRotation,
    default_candidates as default_candidates,
)
from ._model.compensator import (
    compensator_force as compensator_force,
    compensator_potential as compensator_potential,
    compensator_stiffness as compensator_stiffness,
    compensator_torque as compensator_torque,
    eta_exact as eta_exact,
    eta_printed_eq11 as eta_printed_eq11,
    spring_length as spring_length,
)
from ._model.equilibrium import (
    Equilibrium as Equilibrium,
    deflection as deflection,
    equilibrium as equilibrium,
    solve_deflection as solve_deflection,
    solve_equilibrium as solve_equilibrium,
    total_potential as total_potential,
)
from ._model.kinematics import (
    Pose as Pose,
    forward as forward,
    jacobian_theta as jacobian_theta,
    mass_positions as mass_positions,
    tool_point as tool_point,
    wrist_centre as wrist_centre,
)
from ._model.linear import (
    joint_stiffness as joint_stiffness,
    linear_deflection as linear_deflection,
)
from ._model.observation import (
    observation_aggregated as observation_aggregated,
    observation_linear as observation_linear,
    observation_physical as observation_physical,
)
from ._model.quasi_serial import (
    tree_dict_from_quasi_serial as tree_dict_from_quasi_serial,
)
from ._model.robot_files import (
    TREE_PRESETS as TREE_PRESETS,
    load_tree as load_tree,
)
from ._model.simulate import (
    DeflectionError as DeflectionError,
    model_deflections as model_deflections,
    simulate as simulate,
)
from ._model.spring_laws import (
    SPRING_LAWS as SPRING_LAWS,
    CompensatorLaw as CompensatorLaw,
    CompensatorPreloadLaw as CompensatorPreloadLaw,
    JointBacklash as JointBacklash,
    JointHardening as JointHardening,
    SpringLaw as SpringLaw,
)
from ._model.stiffness import (
    cartesian_compliance as cartesian_compliance,
    cartesian_stiffness as cartesian_stiffness,
)
from ._model.tree import TreeRobot as TreeRobot
from ._model.tree_files import (
    tree_from_dict as tree_from_dict,
    tree_to_dict as tree_to_dict,
)
from ._model.tree_kinematics import (
    element_frames as element_frames,
    link_angles as link_angles,
    marker_positions as marker_positions,
)
from ._model.tree_statics import (
    TreeEquilibrium as TreeEquilibrium,
    predict_markers as predict_markers,
    tree_deflection as tree_deflection,
    tree_equilibrium as tree_equilibrium,
)
from ._model.urdf import (
    load_urdf as load_urdf,
    tree_dict_from_urdf as tree_dict_from_urdf,
)
from ._model.urdf_export import save_urdf as save_urdf, tree_to_urdf as tree_to_urdf
from ._parameters import (
    get_parameters as get_parameters,
    parameter_names as parameter_names,
    parameter_units as parameter_units,
    set_parameters as set_parameters,
)
from ._robot import (
    AbstractEffect as AbstractEffect,
    Experiment as Experiment,
    Robot as Robot,
)
from ._robot_file import (
    PRESETS as PRESETS,
    load_robot as load_robot,
    robot_from_dict as robot_from_dict,
    robot_to_dict as robot_to_dict,
)
from ._robot_tree import as_tree as as_tree
from ._solution import RESULTS as RESULTS
from .compensation import (
    Compensation as Compensation,
    compensate as compensate,
    read_path as read_path,
)
from .design import (
    CONSTRAINTS as CONSTRAINTS,
    PAPER_TABLE5_DEG as PAPER_TABLE5_DEG,
    Advice as Advice,
    Design as Design,
    DesignBound as DesignBound,
    DesignCriteria as DesignCriteria,
    DesignProblem as DesignProblem,
    PoolSelection as PoolSelection,
    Selection as Selection,
    TaskPrediction as TaskPrediction,
    TreePlanEvaluation as TreePlanEvaluation,
    advise_measurements as advise_measurements,
    advise_tree as advise_tree,
    constraint_values as constraint_values,
    design_bound as design_bound,
    design_bounds as design_bounds,
    design_criteria as design_criteria,
    design_loads as design_loads,
    design_objective as design_objective,
    design_observation as design_observation,
    evaluate_tree_plan as evaluate_tree_plan,
    feasible_q3_range as feasible_q3_range,
    jaxcal_to_paper as jaxcal_to_paper,
    optimise_design as optimise_design,
    paper_q2 as paper_q2,
    paper_table5_plan as paper_table5_plan,
    paper_to_jaxcal as paper_to_jaxcal,
    random_designs as random_designs,
    rank_random_designs as rank_random_designs,
    select_from_pool as select_from_pool,
    select_rows as select_rows,
    select_tree_rows as select_tree_rows,
    structured_design as structured_design,
    task_information as task_information,
    task_prediction as task_prediction,
    task_value as task_value,
)
from .discrepancy import (
    CandidateResult as CandidateResult,
    DiscoveryReport as DiscoveryReport,
    SuperModel as SuperModel,
    TreeCandidate as TreeCandidate,
    TreeDiscovery as TreeDiscovery,
    TreeEffect as TreeEffect,
    discover as discover,
    discover_batch as discover_batch,
    discover_tree as discover_tree,
    tree_candidates as tree_candidates,
)
from .montecarlo import (
    MonteCarloResult as MonteCarloResult,
    TreeStudy as TreeStudy,
    load_sweep as load_sweep,
    monte_carlo as monte_carlo,
    noise_sweep as noise_sweep,
    plot_error_vs_noise as plot_error_vs_noise,
    plot_histograms as plot_histograms,
    tree_study as tree_study,
    trial_noise as trial_noise,
)

__version__ = "0.1.0"
