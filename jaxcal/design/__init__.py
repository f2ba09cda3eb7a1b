"""Design of experiments: the measurement configurations that make the identified
parameters most precise. Constraints and loads, the covariance criteria (trace,
determinant, weighted, explicit parameter lists) with autodiff gradients, the continuous
constrained optimiser, the approximate-design bound and efficiency, and discrete plans
(random, structured, the paper's Table 5); the task criterion (the error a
calibration leaves on the user's own poses and loads, in mm); exact k-row subsets of a
candidate file (Fedorov exchange) with their efficiency; advice for parameters a data set does
not determine (which further rows, where, how many)."""

from ._advice import (
    Advice as Advice,
    advise_measurements as advise_measurements,
)
from ._advice_tree import advise_tree as advise_tree
from ._bound import (
    DesignBound as DesignBound,
    design_bound as design_bound,
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
from ._evaluate_tree import (
    TreePlanEvaluation as TreePlanEvaluation,
    evaluate_tree_plan as evaluate_tree_plan,
)
from ._optimise import (
    Design as Design,
    DesignProblem as DesignProblem,
    design_objective as design_objective,
    optimise_design as optimise_design,
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
from ._reference import rank_random_designs as rank_random_designs
from ._select import (
    SELECT_CRITERIA as SELECT_CRITERIA,
    Selection as Selection,
    select_rows as select_rows,
)
from ._select_pool import (
    PoolSelection as PoolSelection,
    select_from_pool as select_from_pool,
)
from ._select_tree import select_tree_rows as select_tree_rows
from ._task import (
    TaskPrediction as TaskPrediction,
    task_information as task_information,
    task_prediction as task_prediction,
    task_value as task_value,
)
