"""Host-side identification entry point: input checks, identifiability, then one
method's `init` and its pure `fit` under `jit` (`method.py`).

Identifiability is decided *before* solving, from the σ-weighted design of the linear
model (its columns `∂Δp/∂p`, each scaled by the parameter's prior value, then
normalised): a parameter with no sensitivity, or one taking part in a (numerical)
null direction of the design, cannot be determined by the data. It is named in a
`ValueError` with a suggested `--fix`, or, if the caller fixed it, held at the robot's
value with a warning. No singular matrix is ever inverted.
"""

from __future__ import annotations

import dataclasses
import warnings

import equinox as eqx
import jax
import numpy as np

from .._exported import exported
from .._io import Dataset, q2_groups
from .._linalg.covariance import dead_columns, null_space, nullity
from .._model.linear import linear_deflection
from .._parameters import get_parameters, set_parameters
from .._plausibility import check_loaded, duplicate_rows
from .._precision import require_float64
from .._robot import Robot
from .._solution import messages
from .assembly import held_as_fixed
from .gross import data_snooping
from .method import METHODS, fit_jit, method_named
from .methods import linear_columns
from .result import THRESHOLD, IdentificationResult, residual_warnings, resolve_name

__all__ = [
    "identify",
    "METHODS",
    "identifiability",
    "check_inputs",
    "design_matrix",
    "plausibility",
]

#: Order in which parameters are proposed for fixing (last-resort ones first).
_FIX_PREFERENCE = ("s0_m", "Kc_N_per_m", "k1_urad_per_Nm")


def check_inputs(robot: Robot, data: Dataset) -> None:
    """Raise `ValueError` naming the problem: float64 off (or a float32 robot or data
    set), no deflections, non-finite values, non-positive σ, no load in any row, joint
    angles outside the robot's limits."""
    require_float64("identification", robot.compliance, data.q)
    if data.deflection is None:
        raise ValueError("data has no measured deflections (columns dx_mm, dy_mm, dz_mm)")
    for name in ("q", "force", "moment", "deflection", "sigma"):
        a = np.asarray(getattr(data, name))
        bad = ~np.isfinite(a)
        if bad.ndim > 1:
            bad = bad.any(axis=1)
        if bad.any():
            rows = ", ".join(str(i + 1) for i in np.flatnonzero(bad)[:20])
            raise ValueError(f"data: non-finite (NaN or infinite) {name} in row(s) {rows}")
    if np.any(np.asarray(data.sigma) <= 0):
        raise ValueError("data: sigma must be positive in every row")
    check_loaded(data)
    q = np.asarray(data.q)
    lim = np.asarray(robot.joint_limits)
    tol = 1e-9
    out = (q < lim[:, 0] - tol) | (q > lim[:, 1] + tol)
    if out.any():
        msgs = []
        for r, j in zip(*np.nonzero(out), strict=True):
            msgs.append(
                f"row {r + 1}: q{j + 1} = {np.rad2deg(q[r, j]):.4g} deg outside "
                f"[{np.rad2deg(lim[j, 0]):g}, {np.rad2deg(lim[j, 1]):g}]"
            )
        more = f" ... and {len(msgs) - 10} more" if len(msgs) > 10 else ""
        raise ValueError(
            "data: joint angles outside the joint limits: " + "; ".join(msgs[:10]) + more
        )


@eqx.filter_jit
def _physical_columns(robot: Robot, data: Dataset):
    p0 = get_parameters(robot)

    def one(q, f, m):
        fn = lambda p: linear_deflection(set_parameters(robot, p), q, f, m)[:3]
        return jax.jacfwd(fn)(p0)

    return jax.vmap(one)(data.q, data.force, data.moment)


def design_matrix(robot: Robot, data: Dataset, method: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """σ-weighted, prior-scaled design `(3n, p)` used for the identifiability check and
    its column names. Nonlinear: the linear model's Jacobian w.r.t. all physical
    parameters (the full model's tangent up to gravity/`H_θθ` terms); linear: `k1..k6`;
    two-step: step-1 columns `k1, k2@q2ᵢ.., k3..k6`."""
    p0 = np.asarray(get_parameters(robot))
    sig = np.asarray(data.sigma)[:, None, None]
    if method == "nonlinear":
        cols = np.asarray(_physical_columns(robot, data)) * p0
        names = robot.parameter_names
    else:
        cols, _ = linear_columns(robot, data)
        cols = np.asarray(cols) * p0[:6]
        names = robot.parameter_names[:6]
    return (cols / sig).reshape(-1, cols.shape[2]), names


def identifiability(X: np.ndarray, names: tuple[str, ...]) -> tuple[list[str], list[str]]:
    """Parameters the design `X` (columns ↔ `names`) cannot determine
    (`_linalg.covariance.null_space`), and a minimal set to fix (preferring compensator
    parameters and k1). Host-side."""
    bad = set(np.flatnonzero(null_space(X)).tolist())
    dead = dead_columns(X)
    fix = sorted(int(i) for i in np.flatnonzero(dead))
    cols = [i for i in range(X.shape[1]) if not dead[i]]
    order = sorted(
        [i for i in cols if i in bad],
        key=lambda i: (
            _FIX_PREFERENCE.index(names[i])
            if names[i] in _FIX_PREFERENCE
            else len(_FIX_PREFERENCE) + (len(names) - i)
        ),
    )
    current = nullity(X[:, cols])
    for i in order:
        if current == 0:
            break
        trial = [c for c in cols if c != i]
        n_trial = nullity(X[:, trial])
        if n_trial < current:
            cols, current = trial, n_trial
            fix.append(i)
    return [names[i] for i in sorted(bad)], [names[i] for i in sorted(fix)]


def _reasons(robot: Robot, data: Dataset, bad: list[str]) -> str:
    why = []
    f = np.asarray(data.force)
    m = np.asarray(data.moment)
    if "k1_urad_per_Nm" in bad and np.allclose(f[:, :2], 0) and np.allclose(m[:, :2], 0):
        why.append(
            "every load is vertical, and a vertical force gives no torque about the "
            "(vertical) axis 1, so k1 does not affect the deflections"
        )
    n_q2 = len(q2_groups(data.q[:, 1])[0])
    if robot.has_compensator and {"Kc_N_per_m", "s0_m"} & set(bad) and n_q2 < 3:
        why.append(
            f"the rows have {n_q2} distinct q2 value(s); k2, Kc and s0 act only through the "
            "joint-2 stiffness at each q2, so at least 3 distinct q2 values are needed"
        )
    return ("; ".join(why) + ".") if why else "the design matrix is rank deficient."


def identify(
    robot: Robot,
    data: Dataset,
    method: str = "nonlinear",
    *,
    fix: tuple[str, ...] | list[str] = (),
    robust: bool = False,
    huber_delta: float = 1.5,
    max_steps: int = 64,
    screen_gross: bool = True,
    keep_outliers: bool = False,
    throw: bool = False,
    undetermined: str = "free",
    threshold: float = THRESHOLD,
) -> IdentificationResult:
    """Identify the elastostatic parameters of `robot` from measured `data`.

    **Arguments**

    - `method`: `"nonlinear"` (default; full equilibrium model, Levenberg–Marquardt),
      `"two-step"` (eqs. 20–22) or `"linear"` (eq. 3 on the linear model).
    - `fix`: parameter names (`"k1"` or `"k1_urad_per_Nm"`) held at the robot's value
      (a warning says so).
    - `robust`: Huber loss (threshold `huber_delta` σ) instead of least squares
      (nonlinear method only).
    - `screen_gross`: find gross errors one row at a time (`jaxcal._identification.gross`: the
      w-statistic against a Bonferroni critical value, 0.1 % false alarms per data set)
      and, unless `keep_outliers`, exclude them from the estimates. Named in
      `result.gross_errors()`; a warning says so.
    - `undetermined`: what becomes of a parameter *not determined by these data*
      (relative std above `threshold`, default 10 %, or in the null space of the
      design). `"free"` (default): it keeps its estimate, flagged in
      `result.not_determined` (reports give it no two-sided interval). `"hold"` (what
      the command line does): the fit is repeated with it held at the robot file's value,
      so that a saved robot file or a compensation uses that value; a parameter the
      design cannot determine at all is held instead of raising. Either way
      `result.free_values` keeps its free estimate and std, and `result.bound95` its
      one-sided bound. The two-step method cannot hold k2, Kc or s0: they stay flagged.

    Raises `ValueError` for float64 off, missing deflections, non-finite values, joint
    angles outside the limits, and parameters the data cannot determine (named, with
    the `--fix` that would make the rest identifiable). If the fit did not succeed
    (`result.result` is not `RESULTS.successful`) it warns with the reason, or raises
    `RuntimeError` with it when `throw=True`. Outlier rows: `result.outliers(threshold)`.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if undetermined not in ("free", "hold"):
        raise ValueError(f"undetermined must be 'free' or 'hold', got {undetermined!r}")
    if not threshold > 0:
        raise ValueError(f"threshold must be positive, got {threshold}")
    if robust and method != "nonlinear":
        raise ValueError("robust (Huber) fitting is available for the nonlinear method only")
    check_inputs(robot, data)
    copies = duplicate_rows(data)
    if copies:
        warnings.warn(copies, stacklevel=2)
    names = robot.parameter_names
    fixed = tuple(dict.fromkeys(resolve_name(str(f), names) for f in fix))
    if method == "two-step":
        if not robot.has_compensator:
            raise ValueError("the two-step method needs a robot with a compensator; use linear")
        for n in ("k2_urad_per_Nm", "Kc_N_per_m", "s0_m"):
            if n in fixed:
                raise ValueError(f"the two-step method cannot hold {n} fixed; use nonlinear")
    if method == "linear":
        fixed = tuple(f for f in fixed if f not in ("Kc_N_per_m", "s0_m"))
    X, cols = design_matrix(robot, data, method)
    keep = [i for i, n in enumerate(cols) if n not in fixed]
    bad, suggest = identifiability(X[:, keep], tuple(cols[i] for i in keep))
    if method == "two-step" and not bad:
        n_q2 = len(q2_groups(data.q[:, 1])[0])
        if n_q2 < 3:
            bad, suggest = ["Kc_N_per_m", "s0_m"], []
    user_fixed = fixed
    if bad and undetermined == "hold" and suggest and _holdable(method, suggest):
        # Not determined at all: held like the rest of the undetermined (flagged below).
        fixed = (*fixed, *suggest)
        bad = []
    if bad:
        flags = " ".join("--fix " + s.split("_")[0] for s in suggest)
        short = lambda ns: ", ".join(n.split("_")[0] for n in ns)
        hint = (
            f" Fix them at the robot's values with {flags}"
            f" (Python: fix={tuple(s.split('_')[0] for s in suggest)})."
            if suggest
            else " The two-step method needs at least 3 distinct q2 values; use the "
            "nonlinear method with --fix Kc --fix s0."
        )
        raise ValueError(
            f"the data cannot determine {short(bad)} ({', '.join(bad)}): "
            f"{_reasons(robot, data, bad)}{hint}"
        )
    p0 = np.asarray(get_parameters(robot))
    for n in user_fixed:
        warnings.warn(
            f"{n} is fixed at the robot's value {p0[names.index(n)]:g}; its uncertainty is "
            "not included in the others' standard errors",
            stacklevel=2,
        )

    first = fixed

    def run(fixed: tuple[str, ...]) -> IdentificationResult:
        # The nonlinear fit holds what the loop below adds by a traced mask: one compiled
        # program for every pass (a cold `jaxcal identify` of the example, which holds
        # Kc and then s0: 6.8 s, against 12.7 s with a compile per pass).
        nonlinear = method == "nonlinear"
        base = first if nonlinear else fixed
        held = tuple(n for n in fixed if n not in base)
        settings: dict = {"free": tuple(n not in base for n in names)}
        held_mask = None
        if nonlinear:
            loss = "huber" if robust else "l2"
            settings.update(loss=loss, huber_delta=float(huber_delta), max_steps=int(max_steps))
            # An array in every pass (zeros in the first): one program for all of them.
            held_mask = jax.numpy.asarray([n in held for n in names], robot.compliance.dtype)
        solver = method_named(method, **settings)

        def fit(d: Dataset) -> IdentificationResult:
            state = solver.init(robot, d)
            if held_mask is not None:
                state = dataclasses.replace(state, held=held_mask)
            return held_as_fixed(_fit_stored(solver, state, d.deflection), names, held)

        res = fit(data)
        if screen_gross:
            keep = [i for i, n in enumerate(cols) if n not in fixed]
            res = data_snooping(res, data, X[:, keep], fit, exclude=not keep_outliers)
        return res

    structural = [n for n in fixed if n not in user_fixed]
    free_values = {n: (float("nan"), float("inf")) for n in structural}
    res = run(fixed)
    # Parameters above the threshold: flagged, or held and the fit repeated (holding one
    # can leave another above it, hence the loop; each pass holds at least one more).
    while True:
        rel = res.relative_std()
        over = [n for n, r in zip(res.names, rel, strict=True) if r > threshold]
        for n in over:
            free_values.setdefault(n, res.parameter(n))
        if undetermined == "free" or not over or not _holdable(method, over):
            break
        if all(n in fixed or n in over for n in res.names):
            # Nothing would be left to fit: every estimate is flagged, none held (data
            # this uninformative are said so by the plausibility checks below).
            break
        fixed = (*fixed, *over)
        res = run(fixed)
    flagged = tuple(n for n in names if n in free_values)
    res = dataclasses.replace(
        res,
        threshold=float(threshold),
        not_determined=flagged,
        free_values=tuple(free_values[n] for n in flagged),
    )
    if not bool(res.converged):
        why = messages(res.result)[0] or "it did not converge"
        text = f"the {method} fit failed: {why}; the estimates are not reliable"
        if throw:
            raise RuntimeError(text)
        warnings.warn(text, stacklevel=2)
    for msg in plausibility(robot, res):
        # An estimate the data do not determine says nothing about units.
        if not any(msg.startswith(n.split("_")[0] + " ") for n in flagged):
            warnings.warn(msg, stacklevel=2)
    return res


def _holdable(method: str, names) -> bool:
    # The two-step method estimates k2, Kc and s0 together from the aggregated
    # compliances: it cannot hold any of them.
    return method != "two-step" or not {"k2_urad_per_Nm", "Kc_N_per_m", "s0_m"} & set(names)


def plausibility(robot: Robot, res: IdentificationResult) -> list[str]:
    """Warnings for results that should not pass silently: a χ² that disagrees with the
    stated σ, or no degree of freedom to check it (`residual_warnings`), and estimates
    that are not positive or more than 10× from the robot file's value."""
    out = residual_warnings(float(res.chi2_red) * res.dof, res.dof, "deflections")
    p0 = dict(zip(robot.parameter_names, np.asarray(get_parameters(robot)), strict=True))
    for n, v in zip(res.names, np.asarray(res.estimate), strict=True):
        ref = float(p0[n])
        short = n.split("_")[0]
        if v <= 0:
            out.append(f"{short} estimate {v:.4g} is not positive: no spring has that")
        elif ref > 0 and not ref / 10 <= v <= ref * 10:
            out.append(
                f"{short} estimate {v:.4g} is more than 10x from the robot file's {ref:.4g}: "
                "check the units of the data and of the robot file"
            )
    return out


#: The fit kept traced on disk while the compilation cache is on: tracing the nonlinear
#: fit is most of a warm `jaxcal identify`.
_fit_stored = exported(fit_jit)
