"""Names that tests, benchmarks and notebooks need but that are not part of the stable
public API (as `lineax.internal`): they may change between versions.

The command line is not imported here (nothing in the library imports it); its test
door is the submodule `jaxcal.internal.cli`."""

from .._batching import (
    divide_among_devices as divide_among_devices,
    map_in_chunks as map_in_chunks,
)
from .._cache import cache_info as cache_info, clear_cache as clear_cache
from .._exported import (
    BRIEF_OPTIONS as BRIEF_OPTIONS,
    brief_jit as brief_jit,
    export_directory as export_directory,
    exported as exported,
    set_export_directory as set_export_directory,
)
from .._identification.assembly import make_result as make_result
from .._identification.elastogeometric import (
    JACOBIAN_RTOL as JACOBIAN_RTOL,
    LM_CHI2_TOL as LM_CHI2_TOL,
    scaled_jacobian as scaled_jacobian,
)
from .._identification.gross import (
    critical_w as critical_w,
    data_snooping as data_snooping,
    heldout_gross as heldout_gross,
    marker_w as marker_w,
    w_statistics as w_statistics,
)
from .._identification.lsq import levenberg_marquardt as levenberg_marquardt
from .._identification.method import fit_jit as fit_jit
from .._identification.methods import (
    full_model_predictor as full_model_predictor,
)
from .._identification.parameter_groups import (
    get_vector as get_vector,
    set_vector as set_vector,
)
from .._identification.pivoting import pivoted_subset as pivoted_subset
from .._identification.result import residual_warnings as residual_warnings
from .._identification.tree_validation import split_rows as split_rows
from .._io import (
    OutputError as OutputError,
    atomic_file as atomic_file,
    save_figure as save_figure,
)
from .._linalg import dense as dense
from .._linalg.covariance import (
    covariance_from_jacobian as covariance_from_jacobian,
    masked_covariance as masked_covariance,
    null_space as null_space,
    unidentifiable as unidentifiable,
    well_conditioned as well_conditioned,
)
from .._linalg.iterative import (
    accelerated_solve as accelerated_solve,
    implicit_solve as implicit_solve,
    richardson as richardson,
)
from .._linalg.solvers import linalg_backend as linalg_backend
from .._model.candidates import THETA_REF as THETA_REF
from .._model.rotations import Rx as Rx, Ry as Ry, Rz as Rz, rpy_from_matrix as rpy_from_matrix
from .._model.simulate import batch_deflections as batch_deflections
from .._model.tree_kinematics import gravity_potential as gravity_potential
from .._model.tree_statics import (
    DERIVATIVE_RTOL as DERIVATIVE_RTOL,
    spring_residual as spring_residual,
)
from .._robot import URAD as URAD, G as G
from .._solution import NAMES as NAMES, messages as messages
from ..compensation._tree import robot_covariance as robot_covariance, tree_rows as tree_rows
from ..design._bound import pool_observations as pool_observations
from ..design._criteria import criteria_from_observation as criteria_from_observation
from ..design._observation import screw_jacobian as screw_jacobian
from ..design._pool_bound import pool_bound as pool_bound
from ..design._problem import problem_criteria as problem_criteria
from ..design._reference import pool_values as pool_values
from ..design._select import (
    subset_values as subset_values,
    swap_values as swap_values,
)
from ..design._select_tree import (
    linearised_plan as linearised_plan,
    row_blocks as row_blocks,
    task_weight as task_weight,
)
from ..discrepancy._batch_fit import BatchFit as BatchFit
from ..discrepancy._heldout import (
    LEVERAGE_MAX as LEVERAGE_MAX,
    heldout_residuals as heldout_residuals,
    press as press,
)
from ..discrepancy._report import chi2_sf as chi2_sf
from ..discrepancy._screening import (
    PRELOAD_FACTORS as PRELOAD_FACTORS,
    candidate_free as candidate_free,
    preload_scan as preload_scan,
)
from ..discrepancy._t_optimal import (
    greedy_t_rows as greedy_t_rows,
    lack_of_fit as lack_of_fit,
)
from ..montecarlo._chunk import make_chunk_fn as make_chunk_fn
from ..montecarlo._methods import TrialFit as TrialFit
from ..montecarlo._noise import (
    normal_from_bits as normal_from_bits,
    standard_normal as standard_normal,
)
from ..montecarlo._stats import MomentAccumulator as MomentAccumulator
from ..montecarlo._study import prepare_study as prepare_study, run_study as run_study
