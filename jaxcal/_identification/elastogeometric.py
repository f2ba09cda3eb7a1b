"""Elasto-geometric calibration of a `TreeRobot` from absolute marker measurements.

The measurement frame, the marker offsets, the DH errors and the spring compliances
are fitted jointly by Levenberg–Marquardt through the static equilibrium under the
robot's own weight (`nonlinear_fit`). Which of them the data determine is decided from
the data: QR with column pivoting of the σ-weighted Jacobian at the start (as FIGAROH
does), each column scaled to the parameter's typical size; the columns it does not
pick are named and held at the robot file's values. A fitted spring, mass or spring-law
constant whose relative std exceeds `THRESHOLD` is flagged as *not determined by these
data* (not to be read on its own); it stays fitted unless `hold_undetermined`: 40 of Agile
Justin's 46 fitted springs are flagged one by one, yet together they take the held-out
error from 6.5 mm (held at the file's values) to 2.9 mm (`benchmarks/README.md`).

Optional Gaussian priors (`priors`: a std per group or parameter, centred on the robot
file's values) make the fit a maximum a posteriori estimate: a parameter with a prior
is fitted whatever the data say (the prior determines what they do not; its std is the
posterior one), the pivoting chooses among the others. They let a few rows calibrate a
model with more parameters than the rows determine, and keep near-redundant springs
near their catalogue values.

Every fit of one robot and one data shape shares one compiled program: the fitted
subset and the priors are traced arrays over the full parameter table, not static
choices.
"""

from __future__ import annotations

import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import map_in_chunks, split_map
from .._exported import exported
from .._markers import MarkerData
from .._model.equilibrium import with_zero_wrench
from .._model.tree import TreeRobot
from .._model.tree_statics import DERIVATIVE_RTOL, predict_markers, solver_advice
from .._precision import require_float64
from .._solution import RESULTS, messages
from .gross import INFLATE, snoop_markers
from .lsq import LsqFit, nonlinear_fit
from .parameter_groups import (
    Parameter,
    PriorSpec,
    default_groups,
    get_vector,
    parameter_table,
    pivot_units,
    prior_stds,
    set_vector,
)
from .pivoting import PIVOT_RCOND, fitted_parameters
from .result import THRESHOLD, relative_std, residual_warnings
from .tree_result import TreeCalibration

__all__ = [
    "TreeCalibration",
    "calibrate_tree",
    "fit_markers",
    "pose_markers",
    "predict_rows",
    "scaled_jacobian",
]

#: Levenberg–Marquardt stops when a step changes every parameter by less than this, in
#: units of its typical size (`Parameter.scale`: 1 mm, 1 mrad, 10 µrad/(N·m)).
LM_TOL = 1e-6

#: ... or when the next step predicts a χ² decrease below this: the estimate would move
#: by less than 0.03 standard deviations along it (`StallingLevenbergMarquardt`).
LM_CHI2_TOL = 1e-3

#: Relative accuracy of the equilibrium's implicit derivative in the observation
#: Jacobian (fits, designs), looser than the model's default (`DERIVATIVE_RTOL`): an error
#: of 1e-5 to 3e-5 relative in the Jacobian moves a fit's optimum by ~1e-4 std (it stops
#: at 0.03) and its stds by ~1e-4 relative. Agile Justin's full calibration (300 rows, 152
#: parameters): the same 21 steps, χ² equal to 1e-10 relative, estimates within 3e-4 std,
#: stds within 7e-5 relative and held-out errors within 1e-5 mm of a derivative 100 times
#: tighter, in 16 % less time (two fewer Hessian products per output and pose).
JACOBIAN_RTOL = 1e-4

#: Groups whose parameters are physical magnitudes (a spring, a mass, a law's
#: constant): their relative standard deviation says whether the data determine them.
#: Frame and geometric parameters are errors about zero, decided by the pivoting alone.
MAGNITUDE_GROUPS = (
    "joint-compliance",
    "lateral-compliance",
    "link-compliance",
    "masses",
    "spring-laws",
)


def pose_markers(
    robot: TreeRobot, pose, deflection: bool = False, *, derivative_rtol: float = DERIVATIVE_RTOL
):
    """What a row of `data.poses()` measures: `predict_markers` under the row's load, or
    with `deflection` every marker's displacement when the load is applied (loaded minus
    unloaded at the same angles; the deflection data format)."""
    q, force, moment = pose
    if not deflection:
        return predict_markers(robot, q, force, moment, derivative_rtol=derivative_rtol)
    f, m = with_zero_wrench(force, moment, q.dtype)

    def at(f, m):
        return predict_markers(robot, q, f, m, derivative_rtol=derivative_rtol)

    y, ok = jax.vmap(at)(f, m)
    return y[0] - y[1], ok[0] & ok[1]


def predict_rows(robot: TreeRobot, x, deflection: bool = False):
    """`pose_markers` at every row of `data.poses()` (traceable): `(n, k, 3)` and `(n,)`."""
    return split_map(lambda r, pose: pose_markers(r, pose, deflection), robot, x)


#: Poses per call of the host-side Jacobian (`scaled_jacobian`, from which a fit's start
#: chooses the fitted set): one compiled program serves plans, pools and data of every
#: size (the last call padded with copies of the first pose) instead of one program per
#: size (1–4 s of compile each for Agile Justin's table).
JACOBIAN_CHUNK = 64


# Kept traced on disk (`exported`) while the compilation cache is on: tracing the
# Jacobian and the fit through the tree's equilibria is most of a warm `identify`'s
# wait besides the fit itself.
@exported
@eqx.filter_jit
def _chunk_jacobian(robot, table, x, deflection):
    return _pose_jacobians(robot, table, get_vector(robot, table), x, deflection)[2]


def scaled_jacobian(robot: TreeRobot, table: tuple[Parameter, ...], data: MarkerData) -> np.ndarray:
    """Host-side: the σ-weighted Jacobian `(m, 3, P)` of the `m` seen marker positions of
    `data` (row-major: row, then marker) in the parameters of `table`, each column in
    units of its parameter's typical size (`Parameter.scale`), at `robot`'s values. A
    plan without measurements (`markers=None`) works too."""
    rows, markers = data.observations()
    q, force, moment = data.poses()
    J = map_in_chunks(
        lambda *pose: _chunk_jacobian(robot, table, pose, data.deflection),
        q.shape[0],
        JACOBIAN_CHUNK,
        q,
        force,
        moment,
    )[rows, markers]
    scale = np.asarray([p.scale for p in table])
    return J * scale / np.asarray(data.sigma)[rows][:, None, None]


def _undetermined(table, fitted, est, std, threshold) -> list[int]:
    rel = relative_std(est, std)
    return [
        i
        for i, p in enumerate(table)
        if fitted[i] and p.group in MAGNITUDE_GROUPS and rel[i] > threshold
    ]


def _pose_jacobians(robot: TreeRobot, table, p, x, deflection):
    """Every pose's marker predictions `(n, k, 3)`, ok flags and their Jacobian in `p`
    `(n, k, 3, P)`, by reverse mode pose by pose: a pose has 3k outputs against P ~ 100
    parameters, and the equilibrium's adjoint is one solve per output."""

    def pose(p, x):
        r = set_vector(robot, table, p)
        y, ok = pose_markers(r, x, deflection, derivative_rtol=JACOBIAN_RTOL)
        return y, (y, ok)

    J, (y, ok) = split_map(jax.jacrev(pose, has_aux=True), p, x)
    return y, ok, J


def _jacobian(robot: TreeRobot, table, p, x, deflection, rows, markers):
    """`_pose_jacobians` at the seen markers `(rows, markers)`."""
    y, ok, J = _pose_jacobians(robot, table, p, x, deflection)
    return y[rows, markers], ok, J[rows, markers]


def fit_markers(
    robot, table, mask, x, deflection, rows, markers, target, sigma, scale, prior_weight, max_steps
) -> LsqFit:
    """A calibration's fit, traceable (Monte-Carlo trials map it): `table`'s parameters
    where `mask` is 1, from `robot`'s values, to the seen markers `target` `(m, 3)` (m; at
    `rows`, `markers` of `observations`) at the poses `x`, σ `(m,)`."""

    def jacobian(p):
        return _jacobian(robot, table, p, x, deflection, rows, markers)

    # Given the Jacobian, `nonlinear_fit` never calls the prediction on its own.
    return nonlinear_fit(
        lambda p: jacobian(p)[:2],
        get_vector(robot, table),
        target,
        sigma,
        scale=scale,
        mask=mask,
        jacobian=jacobian,
        prior_weight=prior_weight,
        max_steps=max_steps,
        rtol=LM_TOL,
        atol=LM_TOL,
        chi2_tol=LM_CHI2_TOL,
    )


_fit = exported(eqx.filter_jit(fit_markers))


def calibrate_tree(
    robot: TreeRobot,
    data: MarkerData,
    groups: tuple[str, ...] | None = None,
    *,
    fit_groups: tuple[str, ...] | None = None,
    hold: tuple[str, ...] = (),
    max_steps: int = 300,
    rcond: float = PIVOT_RCOND,
    threshold: float = THRESHOLD,
    hold_undetermined: bool = False,
    priors: dict[str, PriorSpec] | None = None,
    fitted: np.ndarray | None = None,
    screen_gross: bool = False,
    keep_outliers: bool = False,
    warn: bool = True,
) -> TreeCalibration:
    """Calibrate `robot` on `data`, fitting the parameters of `fit_groups` (default:
    `groups`) that the data determine, starting from the robot's values.

    `groups` (default: `default_groups(robot)`) is the parameter table the program is
    built for (keep it the same across fits to share one compilation); `hold` names
    parameters to hold in any case. Fitted magnitudes with a relative std above
    `threshold` are named in `not_determined`; with `hold_undetermined` they are held
    at the robot's values and the fit repeated (until none is left). `priors`: Gaussian
    priors centred on the robot's values, `{group or parameter name: std}` with the std
    in the parameter's printed unit or `"X%"` of its value (`prior_stds`); a parameter
    with a prior is fitted (unless held) whether or not the data determine it.
    `fitted` `(P,)`, where already known for these poses (repeated fits of one plan,
    `linearised_plan(...).fitted`): the parameters to fit, without the start Jacobian
    that chooses them (`hold` and `fit_groups` still apply). `screen_gross`: name the
    marker observations that are gross errors (`gross.py`, one at a time) and
    exclude them from the fit, unless `keep_outliers`. Never raises on a failed fit:
    see `converged` and `message`. With `warn`, a converged fit whose χ² disagrees with
    the stated σ, or that leaves no degree of freedom to check it, says so
    (`warnings.warn`; the standard deviations rest on σ, not on the residuals).
    """
    require_float64("calibration", robot.compliance, np.asarray(data.q))
    if not threshold > 0:
        raise ValueError(f"threshold must be positive, got {threshold}")

    def fit(start, hold, chosen=None, excluded=()):
        args = (groups, fit_groups, hold, max_steps, rcond, priors, chosen, excluded)
        return _calibrate(start, data, *args)

    cal = fit(robot, hold, fitted)
    if screen_gross and cal.converged:
        # From the robot's values, as the first fit: Levenberg–Marquardt started at the
        # estimate, or at its linearised update, takes more steps in the near-redundant
        # directions (Agile Justin's 300 training rows: 30 and 27 steps against 16).
        jac = lambda c: scaled_jacobian(c.robot, c.table, data)
        refit = lambda excluded: fit(robot, hold, cal.fitted, excluded)
        cal = snoop_markers(cal, data, jacobian=jac, refit=refit, exclude=not keep_outliers)
    excluded = cal.excluded
    flagged: dict[str, tuple[float, float]] = {}
    while True:
        over = _undetermined(cal.table, cal.fitted, cal.estimate, cal.std, threshold)
        for i in over:
            flagged.setdefault(cal.table[i].name, (float(cal.estimate[i]), float(cal.std[i])))
        if not over or not hold_undetermined:
            break
        hold = (*hold, *(cal.table[i].name for i in over))
        again = fit(robot, hold, None, excluded)
        cal = again._replace(seconds=again.seconds + cal.seconds, gross=cal.gross)
    names = tuple(p.name for p in cal.table if p.name in flagged)
    if warn and cal.converged:
        measured = "deflections" if data.deflection else "marker positions"
        for msg in residual_warnings(cal.chi2, cal.dof, measured):
            warnings.warn(msg, stacklevel=2)
    return cal._replace(
        not_determined=names,
        free_values=tuple(flagged[n] for n in names),
        threshold=float(threshold),
    )


def _calibrate(
    robot, data, groups, fit_groups, hold, max_steps, rcond, priors, chosen=None, excluded=()
) -> TreeCalibration:
    if data.markers is None:
        raise ValueError("data: no marker measurements to calibrate on")
    t0 = time.perf_counter()
    groups = default_groups(robot, data.deflection) if groups is None else groups
    fit_groups = groups if fit_groups is None else fit_groups
    table = parameter_table(robot, groups)
    names = {p.name for p in table}
    unknown = [h for h in hold if h not in names]
    if unknown:
        raise ValueError(f"hold: unknown parameter(s) {unknown}")
    rows, markers = data.observations()
    x = data.poses()
    q = x[0]
    sigma = np.asarray(data.sigma)[rows].copy()
    sigma[list(excluded)] *= INFLATE  # out of the fit, in the same program
    target = jnp.asarray(np.asarray(data.markers)[rows, markers])
    scale = jnp.asarray([p.scale for p in table])
    want = np.array([p.group in fit_groups and p.name not in hold for p in table])
    prior = prior_stds(robot, table, priors)
    has_prior = np.isfinite(prior)
    if chosen is None:
        # The start Jacobian, only where the pivoting has parameters to choose among.
        start = lambda: scaled_jacobian(robot, table, data).reshape(-1, len(table))
        fitted = fitted_parameters(start, want, has_prior, rcond, pivot_units(robot, table))
    else:
        if np.shape(chosen) != (len(table),):
            raise ValueError(f"fitted must have shape ({len(table)},), got {np.shape(chosen)}")
        fitted = np.asarray(chosen, bool) & want
    fit = _fit(
        robot,
        table,
        jnp.asarray(fitted, q.dtype),
        x,
        data.deflection,
        rows,
        markers,
        target,
        jnp.asarray(sigma),
        scale,
        jnp.asarray(np.where(has_prior, 1.0 / prior, 0.0), q.dtype),
        max_steps,
    )
    est = np.asarray(fit.estimate)
    std = np.sqrt(np.clip(np.diag(np.asarray(fit.covariance)), 0.0, None))
    res = np.delete(np.asarray(fit.residuals), list(excluded), axis=0)
    converged = bool(fit.result == RESULTS.successful)
    advice = solver_advice(robot) if fit.result == RESULTS.equilibrium_failed else ""
    return TreeCalibration(
        robot=set_vector(robot, table, jnp.asarray(est)),
        table=table,
        fitted=fitted,
        estimate=est,
        std=std,
        rms_mm=float(np.sqrt(np.mean(np.sum(res**2, axis=-1))) * 1e3),
        chi2=float(fit.chi2),
        dof=int(res.size + (fitted & has_prior).sum() - fitted.sum()),
        converged=converged,
        message="" if converged else messages(fit.result)[0] + advice,
        fit=fit,
        seconds=time.perf_counter() - t0,
        prior_std=prior if priors else None,
        excluded=tuple(excluded),
    )
