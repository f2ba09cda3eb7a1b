"""Generate and execute notebooks/02_identification.ipynb (run from the repo root)."""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

cells = [
    (
        "md",
        "# Identification with uncertainties\n\nIdentify the elastostatic parameters "
        "of the built-in robot from the example calibration data set (48 rows, σ = 0.02 mm) "
        "with the three methods, compare them with the true values, look at the residuals, "
        "and see what each method gets wrong.",
    ),
    (
        "code",
        'import jax\njax.config.update("jax_enable_x64", True)\n'
        "import jaxcal\n"
        "jaxcal.enable_compilation_cache()  # compiled programs kept on disk (jaxcal cache info)\n"
        "%matplotlib inline\nimport json\nimport numpy as np\nimport matplotlib.pyplot as plt\n"
        "import jaxcal\nfrom jaxcal import identify\nfrom jaxcal import format_table",
    ),
    (
        "code",
        "robot = jaxcal.load_robot()\n"
        "data = jaxcal.read_dataset('../tests/data/example_calibration.csv', robot)\n"
        "t = json.loads(open('../tests/data/example_calibration.truth.json').read())\n"
        "truth = dict(zip(robot.parameter_names, t['joint_compliance_urad_per_Nm'] + "
        "[t['compensator']['Kc_N_per_m'], t['compensator']['s0_m']]))\nlen(data), truth",
    ),
    (
        "md",
        "## Three methods\n\n`nonlinear` fits the full equilibrium model (gravity, "
        "load geometry); `two-step` is the paper's eqs. (20)–(22) on the linear model; "
        "`linear` is eq. (3) with the compensator held at the preset.",
    ),
    (
        "code",
        "res = {m: identify(robot, data, m) for m in ('nonlinear', 'two-step', 'linear')}\n"
        "rows = []\nfor n in robot.parameter_names:\n    row = [n, truth[n]]\n"
        "    for m, r in res.items():\n        if n in r.names:\n"
        "            i = r.names.index(n)\n            v, s = float(r.estimate[i]), float(r.std[i])\n"
        "            row += [f'{v:.5g} ± {s:.2g}', f'{(v - truth[n]) / s:+.1f}']\n"
        "        else:\n            row += ['(fixed)', '']\n    rows.append(row)\n"
        "hdr = ['parameter', 'true']\nfor m in res:\n    hdr += [m, 'err/std']\n"
        "print(format_table(hdr, rows))\nfor m, r in res.items():\n"
        "    print(f'{m:10s} rms {float(r.rms)*1e3:.4f} mm  chi2_red {float(r.chi2_red):.3f}')",
    ),
    (
        "md",
        "The nonlinear estimates are within a few standard errors of the truth and its "
        "reduced χ² is ≈ 1. The compensator (Kc, s0) adds only ~1 % to the joint-2 stiffness, "
        "so at 20 µm noise its parameters are poorly determined: their standard errors are "
        "large, honestly so.",
    ),
    ("md", "## Residuals"),
    (
        "code",
        "fig, axs = plt.subplots(1, 3, figsize=(13, 3.2), sharey=True)\n"
        "for ax, (m, r) in zip(axs, res.items()):\n    z = np.asarray(r.standardized)\n"
        "    for k, c in enumerate('xyz'):\n        ax.plot(np.arange(1, len(z) + 1), z[:, k], 'o', ms=3, label=c)\n"
        "    ax.axhline(3, color='k', lw=0.5); ax.axhline(-3, color='k', lw=0.5)\n"
        "    ax.set_title(f'{m}: chi2_red {float(r.chi2_red):.2f}'); ax.set_xlabel('row')\n"
        "axs[0].set_ylabel('residual / σ'); axs[0].legend(); plt.tight_layout()",
    ),
    (
        "md",
        "## What the linear model gets wrong\n\nThe linear model (eq. 5) ignores the "
        "gravity pre-deflection and the load geometry (`H_θθ`). Compare it with the full "
        "equilibrium model on the same rows, both at the nonlinear estimate (within a few "
        "standard errors of the truth). The full model's prediction there is simply the "
        "data minus the fit's residuals, so no new model evaluation is needed:",
    ),
    (
        "code",
        "nl = res['nonlinear']\n"
        "fitted = jaxcal.set_parameters(robot, nl.estimate)\n"
        "full = np.asarray(data.deflection - nl.residuals)\n"
        "lin = np.asarray(jax.vmap(lambda q, f: jaxcal.linear_deflection(fitted, q, f)[:3])"
        "(data.q, data.force))\nerr = np.linalg.norm(full - lin, axis=1) * 1e6\n"
        "print(f'|full - linear| per row: max {err.max():.1f} µm, mean {err.mean():.1f} µm '\n"
        "      f'(noise σ = 20 µm per coordinate)')\n"
        "plt.figure(figsize=(6, 3)); plt.bar(np.arange(1, len(err) + 1), err)\n"
        "plt.xlabel('row'); plt.ylabel('µm'); plt.title('linear-model error at the nonlinear estimate')",
    ),
    (
        "md",
        "That model error is systematic, so the linear and two-step estimates are "
        "biased by several of their (too small) standard errors, and their χ² is inflated; "
        "the two-step compensator parameters absorb the error (s0 is off by many std). "
        "The two-step method also depends on using the *exact* eq. (22) (`sin² q2`); on "
        "noise-free data of its own model, the printed `sin q2` gives wrong compensator "
        "parameters:",
    ),
    (
        "code",
        "from jaxcal import fit_two_step\n"
        "own = data.with_deflection(jax.vmap(lambda q, f: jaxcal.linear_deflection(robot, q, f)[:3])"
        "(data.q, data.force))\nfor exact in (True, False):\n"
        "    r = fit_two_step(robot, own, exact=exact)\n"
        "    print('exact sin²' if exact else 'printed sin', dict(zip(r.names[6:], "
        "np.round(np.asarray(r.estimate[6:]), 4))))",
    ),
]

nb = nbformat.v4.new_notebook()
for kind, src in cells:
    nb.cells.append(
        nbformat.v4.new_markdown_cell(src) if kind == "md" else nbformat.v4.new_code_cell(src)
    )
nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
out = Path("notebooks/02_identification.ipynb")
NotebookClient(
    nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": "notebooks"}}
).execute()
nbformat.write(nb, out)
print("wrote", out)
