"""Generate and execute notebooks/07_real_robot.ipynb (run from the repo root).

The notebook reads one setting, the environment variable `JAXCAL_NOTEBOOK_SCALE`:
`full` (the default, what is committed) or `ci` (reduced settings for the test suite).
Run this script with the variable unset to write the committed outputs.
"""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

cells = [
    (
        "md",
        "# A real robot: DLR's Agile Justin\n\n"
        "Everything so far used simulated measurements. Here jaxcal calibrates a real "
        "elastic robot from its published measurements: the upper body of DLR's humanoid "
        "Agile Justin (a torso with a passive parallelogram joint and two 7-joint arms), "
        "500 poses, each with the positions of one marker on each hand measured by a "
        "camera system. There is no external load: every deflection comes from the "
        "robot's own weight.\n\n"
        "Data and published results: J. Tenhumberg and B. Bäuml, *Calibration of an "
        "Elastic Humanoid Upper Body and Efficient Compensation for Motion Planning*, "
        "IEEE-RAS Humanoids 2021 (arXiv 2311.08333); the data set is "
        "`dataset/measurements.csv` of the repository `dlr-alr/dlr-elastic-calibration`. "
        "Cite that paper wherever these data are used.\n\n"
        "1. the data file and how the robot is described;\n"
        "2. the published protocol: 200 poses held out, the parameter groups added in "
        "turn, the held-out errors beside the published ones;\n"
        "3. the held-out errors before and after calibration;\n"
        "4. the identified joint and lateral compliances with their uncertainties.\n\n"
        "**Settings.** The full protocol takes several minutes on a laptop-class CPU. "
        "The notebook reads one setting, the environment variable "
        "`JAXCAL_NOTEBOOK_SCALE`: `full` (the default; the outputs saved here) or `ci`, "
        "the reduced settings the test suite runs (fewer training poses, only the "
        "frames and joint-compliance stages). The numbers of a `ci` run are therefore "
        "not the ones discussed below.",
    ),
    (
        "code",
        "import jax\n"
        'jax.config.update("jax_enable_x64", True)\n'
        "import csv, json, os, time\n"
        "import jaxcal\n"
        "from jaxcal.internal import split_rows\n"
        "jaxcal.enable_compilation_cache()  # compiled programs kept on disk (jaxcal cache info)\n"
        "%matplotlib inline\n"
        "import numpy as np, matplotlib.pyplot as plt\n"
        "# 'full' (default): the protocol the text describes; 'ci': the test suite's reduced\n"
        "# settings (100 training poses, frames and joint-compliance stages; same code)\n"
        "SCALE = os.environ.get('JAXCAL_NOTEBOOK_SCALE', 'full')\n"
        "assert SCALE in ('full', 'ci'), SCALE\n"
        "FULL = SCALE == 'full'\n"
        "print('scale:', SCALE)",
    ),
    (
        "md",
        "## 1. The data and the robot\n\n"
        "`tests/data/dlr_agile_justin.csv` holds the published numbers unchanged, in "
        "the units of its column names (`tests/data/convert_dlr_agile_justin.py` "
        "converts the published file): the published row index `id`, the 19 commanded "
        "joint angles `q1_deg..q19_deg` (torso 3, right arm 7, left arm 7, head 2), and "
        "the two hand markers in the camera frame, `right_x_mm..` and `left_x_mm..`.",
    ),
    (
        "code",
        'path = "../tests/data/dlr_agile_justin.csv"\n'
        "with open(path, newline='') as f:\n"
        "    raw = list(csv.reader(f))\n"
        "head = raw[0]\n"
        "show = [0, 1, 2, 3, 4, 20, 21, 22, 23, 24, 25]  # id, torso, first right-arm joint, markers\n"
        "print('  '.join(f'{head[i]:>11s}' for i in show))\n"
        "for r in raw[1:5]:\n"
        "    print('  '.join(f'{float(r[i]):11.3f}' for i in show))\n"
        "print(f'{len(raw) - 1} rows, {len(head)} columns')",
    ),
    (
        "md",
        "`jaxcal.read_markers` reads and checks such a file against a robot (column names, "
        "joint limits, finite numbers) and returns the angles in rad and the markers in m; "
        "a marker that was not seen would be a blank cell.",
    ),
    (
        "code",
        'robot = jaxcal.load_tree("dlr_agile_justin")\n'
        "data = jaxcal.read_markers(path, robot)\n"
        "print(f'{len(data)} poses, q {data.q.shape} rad, markers {data.markers.shape} m')\n"
        "for name, seen in zip(robot.marker_names, np.asarray(data.seen).sum(axis=0)):\n"
        "    print(f'marker {name!r}: seen in {seen} of {len(data)} poses')\n"
        "print(f'σ of each coordinate: {float(data.sigma[0]) * 1e3:g} mm (the robot file\\'s noise_std_mm)')",
    ),
    (
        "md",
        "The robot is the preset `dlr_agile_justin` (`jaxcal/robots/dlr_agile_justin.json`): "
        "the nominal kinematics and masses that DLR published, as a kinematic tree of "
        "elements in the modified (Craig) DH convention. Each element has a parent, a "
        "fixed origin or a DH row, the active joints its angle follows (`coupling`), and "
        "springs: one about its joint axis (κθ) and two lateral ones (κα, κβ), all zero "
        "in the preset since they are what we calibrate. The fourth torso element is "
        "passive: its angle is −q2 − q3 (a parallelogram that keeps the chest upright). "
        "Point masses sit on the links; the markers on the two tool frames. The preset's "
        "marker positions and camera-to-robot frame are the data set page's initial "
        "guesses: the `frames` group fits them.",
    ),
    (
        "code",
        "rows = []\n"
        "for e, name in enumerate(robot.names):\n"
        "    parent = robot.names[robot.parents[e]] if robot.parents[e] >= 0 else '(base)'\n"
        "    follows = ' '.join(f'{c:+g}·{robot.joint_names[j]}' for j, c in robot.coupling[e]) or 'fixed'\n"
        "    kg = sum(float(m) for m, k in zip(robot.mass_kg, robot.mass_element) if k == e)\n"
        "    markers = ','.join(m for m, k in zip(robot.marker_names, robot.marker_element) if k == e)\n"
        "    rows.append([name, parent, follows, 'yes' if any(robot.springs[e]) else '',\n"
        "                 round(kg, 3) if kg else '', markers])\n"
        "print(jaxcal.format_table(['element', 'parent', 'angle', 'springs', 'mass kg', 'marker'], rows))\n"
        "print(f'\\ntotal mass {float(robot.mass_kg.sum()):.2f} kg; gravity {np.asarray(robot.gravity)} m/s²')",
    ),
    (
        "md",
        "`jaxcal.tree_to_dict` gives the robot as the JSON of a robot file (what "
        "`jaxcal.save_tree` writes and `jaxcal.load_tree` reads): here the passive torso "
        "element, a hand marker and the measurement frame.",
    ),
    (
        "code",
        "d = jaxcal.tree_to_dict(robot)\n"
        "print(sorted(d))\n"
        "torso_4 = next(el for el in d['elements'] if el['name'] == 'torso_4')\n"
        "print(json.dumps(torso_4, ensure_ascii=False))\n"
        "print(json.dumps(d['markers'][0]))\n"
        "print(json.dumps(d['world']), '| lateral springs:', d['lateral_springs'])",
    ),
    (
        "md",
        "## 2. The published protocol\n\n"
        "200 poses drawn at random are held out; the robot is calibrated on the other "
        "300, adding the parameter groups in turn as the paper's table does: the "
        "measurement `frames` (camera to robot base, the two marker offsets), then the "
        "`joint-offsets`, all `dh` parameters (d, a, α), the `joint-compliance` springs "
        "and the `lateral-compliance` springs. Each stage is one calibration of the "
        "groups so far, from the preset's values; after it, the 3-D marker errors on "
        "the held-out poses. In every stage QR with column pivoting of the Jacobian "
        "decides which parameters of those groups the data determine; the others are "
        "held (`fitted` counts the fitted ones). Each fit is Levenberg–Marquardt "
        "through the static equilibrium under the robot's weight, with a budget of "
        "steps (`max_steps` of `jaxcal.calibrate_tree`, 300 by default); `converged` "
        "says whether it met its tolerances within them. "
        "`jaxcal.validate_tree` runs this protocol (`jaxcal validate` on the command "
        "line).\n\n"
        "At `ci` scale: 100 training poses, only the `frames` and `joint-compliance` "
        "stages.",
    ),
    (
        "code",
        "train_rows, test_rows = split_rows(len(data), 200, 0)\n"
        "if FULL:\n"
        "    groups = jaxcal.default_groups(robot)  # the default: geometry and springs\n"
        "else:\n"
        "    groups = ('frames', 'joint-compliance')\n"
        "    train_rows = train_rows[:100]\n"
        "train, test = data.subset(train_rows), data.subset(test_rows)\n"
        "print(f'calibrating on {len(train)} poses, testing on {len(test)}; groups {groups}')\n\n"
        "t0 = time.perf_counter()\n"
        "def progress(s):\n"
        "    print(f'+ {s.groups[-1]:18s} held-out mean {s.mean_mm:6.2f} mm, {s.fitted:3d} fitted, '\n"
        "          f'converged {s.converged}, {s.seconds:5.1f} s', flush=True)\n"
        "stages = jaxcal.validate_tree(robot, train, test, groups, progress=progress)\n"
        "print(f'validation: {time.perf_counter() - t0:.0f} s')",
    ),
    (
        "code",
        "PUBLISHED = {  # Tenhumberg & Bäuml 2021, table 'Calibration results': mean, std, max mm\n"
        "    'frames': (21.33, 9.71, 63.41),\n"
        "    'joint-offsets': (18.18, 7.80, 45.9),\n"
        "    'dh': (10.5, 5.74, 36.37),\n"
        "    'joint-compliance': (5.64, 2.57, 12.83),\n"
        "    'lateral-compliance': (3.12, 1.71, 8.23),\n"
        "}\n"
        "table = []\n"
        "for s in stages:\n"
        "    g = s.groups[-1]\n"
        "    table.append(['+ ' + g, round(s.mean_mm, 2), round(s.std_mm, 2), round(s.max_mm, 2),\n"
        "                  '/'.join(f'{v:g}' for v in PUBLISHED[g]), round(s.train_rms_mm, 2),\n"
        "                  s.fitted, 'yes' if s.converged else 'NO', round(s.seconds, 1)])\n"
        "print('3-D marker error on the held-out poses, mm')\n"
        "print(jaxcal.format_table(['stage', 'mean', 'std', 'max', 'published mean/std/max',\n"
        "                           'train rms', 'fitted', 'converged', 's'], table))\n"
        "if not FULL:\n"
        "    print('(ci scale: reduced settings; the published figures are for the full protocol)')",
    ),
    (
        "md",
        "**What the table shows** (full settings, one random split, seed 0). Every "
        "stage converged within its step budget. The nominal robot with only the frames "
        "fitted misses by 20.29 mm on average (published 21.33): the public kinematics "
        "and masses reproduce the published starting point. Each group lowers the "
        "held-out error as in the paper, and at every stage our mean and std are at or "
        "below the published ones: joint offsets 17.52 mm (18.18), all DH parameters "
        "10.31 mm (10.5), joint compliances 4.70 mm (5.64), lateral compliances "
        "2.87 mm (3.12). The maxima are lower too except after the joint compliances "
        "(14.25 mm against 12.83). The full calibration reaches 2.87 / 1.49 / 8.05 mm "
        "(mean / std / max) against the published 3.12 / 1.71 / 8.23. The paper's "
        "split is not published, and the split alone moves these figures: on seeds 1 "
        "and 2 (`jaxcal validate tests/data/dlr_agile_justin.csv --robot "
        "dlr_agile_justin --seed 1`; all three in `benchmarks/README.md`) the frames-only "
        "mean is 19.45 and 20.24 mm, and the full calibration gives 3.02 / 1.54 / 8.26 "
        "and 2.84 / 1.39 / 8.88 mm. Its mean is below the published 3.12 mm on all three "
        "splits, its max below the published 8.23 mm on this one only. So read the "
        'comparison as "the same or slightly better on average", not as a ranking.',
    ),
    (
        "md",
        "## 3. Before and after\n\n"
        "The held-out errors of the nominal robot with only the measurement frames "
        "fitted, and after the full calibration: the first and last stage of "
        "`validate_tree`, whose `Stage.calibration` is the `jaxcal.calibrate_tree` "
        "result of that stage (the call `jaxcal identify` makes for a tree robot). "
        "The last line says whether the largest held-out error is one that the "
        "gross-error test names (`Stage.gross`, as `jaxcal validate` prints it below its "
        "table) or the model's own.",
    ),
    (
        "code",
        "frames_cal, cal = stages[0].calibration, stages[-1].calibration\n"
        "for name, c in (('frames only', frames_cal), ('full calibration', cal)):\n"
        '    print(f\'{name:16s}: converged {"yes" if c.converged else "NO, " + c.message}, \'\n'
        "          f'{int(c.fit.steps)} steps, '\n"
        "          f'{int(c.fitted.sum())} of {len(c.table)} parameters fitted, '\n"
        "          f'train rms {c.rms_mm:.2f} mm, {c.seconds:.1f} s')\n"
        "before = jaxcal.marker_errors(frames_cal.robot, test) * 1e3\n"
        "after = jaxcal.marker_errors(cal.robot, test) * 1e3\n"
        "for label, e, s in (('before', before, stages[0]), ('after', after, stages[-1])):\n"
        "    print(f'{label:6s} held-out mean {e.mean():6.2f}  std {e.std():5.2f}  max {e.max():6.2f} mm '\n"
        "          f'(table: {s.mean_mm:.2f} / {s.std_mm:.2f} / {s.max_mm:.2f})')\n"
        "# Is the largest held-out error the data's (a gross error, named by the test identify\n"
        "# applies to its data) or the model's?\n"
        "named = stages[-1].gross_list(test, robot.marker_names)\n"
        "print('held-out gross errors after the full calibration:', named or 'none named',\n"
        "      f'(max without them {stages[-1].max_kept_mm:.2f} mm)')",
    ),
    (
        "code",
        "bins = np.linspace(0, max(before.max(), after.max()) * 1.02, 50)\n"
        "fig, ax = plt.subplots(figsize=(9, 4.5))\n"
        "last = groups[-1]\n"
        "ax.hist(before, bins, alpha=0.6, color='tab:red', label='before: nominal robot, frames fitted')\n"
        "ax.hist(after, bins, alpha=0.6, color='tab:blue',\n"
        "        label='after: full calibration' if FULL else f'after: + {last} (ci)')\n"
        "for g, c, what in (('frames', 'tab:red', 'frames only'), (last, 'tab:blue', f'+ {last}')):\n"
        "    ax.axvline(PUBLISHED[g][0], color=c, ls='--', lw=1.5,\n"
        "               label=f'published mean, {what}: {PUBLISHED[g][0]:g} mm')\n"
        "for e, c in ((before, 'tab:red'), (after, 'tab:blue')):\n"
        "    ax.axvline(e.mean(), color=c, lw=1.5, label=f'mean here: {e.mean():.2f} mm')\n"
        "ax.set_xlabel('3-D marker error on the held-out poses (mm)')\n"
        "ax.set_ylabel('markers')\n"
        "ax.set_title(f'Agile Justin: {len(test)} held-out poses, two markers each')\n"
        "ax.legend()\n"
        "fig.tight_layout()",
    ),
    (
        "md",
        "Before calibration the held-out errors spread up to 56 mm; after the full "
        "calibration none exceeds 8.05 mm and the bulk lies between 1 and 5 mm. The "
        "dashed lines are the published means of the same two stages, the solid ones "
        "ours.",
    ),
    (
        "md",
        "## 4. The identified compliances\n\n"
        "The springs of the full calibration (`cal.table`, `cal.fitted`, `cal.estimate`, "
        "`cal.std`), in µrad/(N·m): each `Parameter` carries its `unit` and the `factor` "
        "from SI. The standard deviations are the fit's covariance with the robot file's "
        "σ = 1 mm per coordinate; the residuals are larger than that (√(χ²/dof) is "
        "printed), so scale them up by that factor for a realistic figure. The springs "
        "that the pivoted QR did not pick are held at their preset value, zero "
        "(`cal.held`).",
    ),
    (
        "code",
        "springs = [(p, f, v, s) for p, f, v, s in zip(cal.table, cal.fitted, cal.estimate, cal.std)\n"
        "           if p.group in ('joint-compliance', 'lateral-compliance')]\n"
        "print(jaxcal.format_table(\n"
        "    ['parameter', 'group', 'value', '± std', 'unit'],\n"
        "    [[p.name, p.group, round(float(v * p.factor), 2), round(float(s * p.factor), 2), p.unit]\n"
        "     for p, f, v, s in springs if f]))\n"
        "print(f'\\n√(χ²/dof) = {np.sqrt(cal.chi2 / cal.dof):.2f} (σ = 1 mm per coordinate assumed)')\n"
        "held = [n for n in cal.held if n.endswith(('.k_theta', '.k_alpha', '.k_beta'))]\n"
        "print(f'\\nheld springs ({len(held)}):', ', '.join(held))\n"
        "print(f'held parameters of the other groups ({len(cal.held) - len(held)}):',\n"
        "      ', '.join(n for n in cal.held if n not in held))",
    ),
    (
        "code",
        "kinds = {'k_theta': ('o', 'joint κθ', -0.2), 'k_alpha': ('s', 'lateral κα', 0.0),\n"
        "         'k_beta': ('^', 'lateral κβ', 0.2)}\n"
        "fitted = [(p.name.rsplit('.', 1), v * p.factor, s * p.factor) for p, f, v, s in springs if f]\n"
        "elements = [n for n in robot.names if any(e == n for (e, _), *_ in fitted)]\n"
        "parts = [[e for e in elements if e.startswith('torso')], [e for e in elements if not e.startswith('torso')]]\n"
        "fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), width_ratios=[len(p) + 1 for p in parts])\n"
        "for ax, part in zip(axes, parts):\n"
        "    for kind, (m, label, off) in kinds.items():\n"
        "        pts = [(part.index(e), v, s) for (e, k), v, s in fitted if k == kind and e in part]\n"
        "        if pts:\n"
        "            x, y, err = map(np.array, zip(*pts))\n"
        "            ax.errorbar(x + off, y, yerr=err, fmt=m, capsize=3, label=label, color=f'C{list(kinds).index(kind)}')\n"
        "    ax.axhline(0, color='k', lw=0.5)\n"
        "    ax.set_xticks(range(len(part)), part, rotation=45, ha='right')\n"
        "    ax.set_xlim(-0.6, len(part) - 0.4)\n"
        "axes[0].set_ylabel('compliance (µrad/(N·m)) ± 1σ')\n"
        "axes[0].set_title('torso')\n"
        "axes[1].set_title('arms')\n"
        "axes[1].legend(ncols=3)\n"
        "fig.suptitle('Identified compliances of Agile Justin (held springs not shown)')\n"
        "fig.tight_layout()",
    ),
    (
        "md",
        "**Reading the springs** (full settings). The torso carries the weight of both "
        "arms and its springs are the best determined: its joint compliances are "
        "positive (180 to 300 µrad/(N·m)) with standard deviations of 3 to 14, though "
        "two of its lateral springs come out negative (−69 ± 13 and −57 ± 14). The arm springs "
        "are larger and far less certain (standard deviations of hundreds to thousands "
        "of µrad/(N·m), before the factor 1.86 above), and several are negative by more "
        "than two standard deviations. A "
        "negative compliance is not a physical spring: with the robot's own weight as "
        "the only load, these parameters absorb whatever gravity-dependent error the "
        "model lacks, and the held-out table above, not their values, is what shows "
        "that they help. Held: the pan axis's κθ (vertical: no gravity torque), the "
        "head's springs (its joints stay at zero), the last wrist joints' κθ and the "
        "springs whose columns the pivoted QR found too small or dependent on others, "
        "as listed above.",
    ),
    (
        "md",
        "## 5. How many poses? Rows chosen for the task\n\n"
        "Which of the 300 training rows would have been worth measuring? `jaxcal design "
        "--robot dlr_agile_justin --pool TRAIN.csv --select K --criterion task --task "
        "TEST.csv` chooses K rows for the *task criterion*: the mean square marker error "
        "the calibration is predicted to leave on the 200 test poses (their poses only, "
        "not their measurements), `--criterion det` for D-optimality. Each subset is "
        "calibrated with the same weak Gaussian priors on every group, centred on the robot "
        "file's values (frames 100 mm/deg, joint offsets 2°, DH 5 mm/deg, springs 100 "
        "µrad/(N·m): the file's springs are rigid, and the prior spans the sizes such an "
        "arm's springs have), so that a subset with fewer "
        "rows than parameters still gives an answer, and compared with random subsets of "
        "the same size. One calibration takes seconds to a minute, so the study is run by "
        "`benchmarks/bench_justin_subsets.py` and its results are loaded here "
        "(`07_justin_subsets.json`: 100 random subsets per size).",
    ),
    (
        "code",
        "study = json.load(open('07_justin_subsets.json'))\n"
        "ks = sorted({r['k'] for r in study})\n"
        "def means(k, label):\n"
        "    return [r['mean_mm'] for r in study if r['k'] == k and r['subset'].startswith(label)]\n"
        "rand = [np.array(means(k, 'random')) for k in ks]\n"
        "rows = [[k, means(k, 'task')[0], means(k, 'det')[0], np.median(r),\n"
        "         np.percentile(r, 10), np.percentile(r, 90), len(r)] for k, r in zip(ks, rand)]\n"
        "print(jaxcal.format_table(['k', 'task', 'det', 'random median', '10 %', '90 %', 'random'],\n"
        "                          [[round(v, 2) if isinstance(v, float) else v for v in row]\n"
        "                           for row in rows]))\n"
        "fig, ax = plt.subplots(figsize=(9, 4.5))\n"
        "ax.fill_between(ks, [r[4] for r in rows], [r[5] for r in rows], color='tab:gray',\n"
        "                alpha=0.3, label='random subsets, 10–90 %')\n"
        "ax.plot(ks, [r[3] for r in rows], 'o-', color='tab:gray', label='random subsets, median')\n"
        "ax.plot(ks, [r[1] for r in rows], 's-', color='tab:blue', label='chosen for the task')\n"
        "ax.plot(ks, [r[2] for r in rows], '^--', color='tab:orange', label='chosen for D')\n"
        "ax.set_xscale('log')\n"
        "ax.set_xticks(ks, [str(k) for k in ks])\n"
        "ax.set_xlabel('calibration rows k (of the 300 training rows)')\n"
        "ax.set_ylabel('held-out mean marker error (mm)')\n"
        "ax.set_title('Agile Justin: 200 held-out poses, calibrated on k rows (priors on every group)')\n"
        "ax.legend()\n"
        "fig.tight_layout()",
    ),
    (
        "code",
        "# The design's promise, from the study: k chosen rows against random subsets of\n"
        "# twice the size, and the chosen 100 against all 300.\n"
        "med = dict(zip(ks, [r[3] for r in rows]))\n"
        "task = dict(zip(ks, [r[1] for r in rows]))\n"
        "for k in (30, 50):\n"
        "    if 2 * k in med:\n"
        "        print(f'{k} rows chosen for the task: {task[k]:.2f} mm; median random {2 * k}: '\n"
        "              f'{med[2 * k]:.2f} mm; median random {k}: {med[k]:.2f} mm')\n"
        "if 100 in task and 300 in task:\n"
        "    print(f'100 chosen: {task[100]:.2f} mm, all 300: {task[300]:.2f} mm '\n"
        "          f'(+{100 * (task[100] / task[300] - 1):.1f} %)')",
    ),
    (
        "md",
        "**What the figure shows** (seed 0's split; `bench_justin_subsets.py --k 10 15 20 30 "
        "50 60 100 300 --random 100`; the numbers are printed above). Rows chosen for the task "
        "beat the median random subset of the same size at every k below 300, and the 100 "
        "chosen rows come within 10 % of all 300. They do not halve the measurements at "
        "k = 30 or 50: the median random subset of twice the size does better. The error "
        "falls with every row added towards the model's own misfit (all 300 rows end near the "
        "full calibration of section 2, which has no priors); the task criterion is a prediction "
        "linearised at the robot file's values, tens of mm off (section 2), which limits "
        "what choosing the rows can gain on this robot. The springs' prior matters: with a "
        "std of 5 µrad/(N·m) around the file's rigid springs (up to 34 std below the springs "
        "the 300 rows determine) every subset's error was 1.6 to 2.3 times as large (30 rows "
        "chosen: 7.8 mm), the criterion taking the springs as known.",
    ),
]

nb = nbformat.v4.new_notebook()
for kind, src in cells:
    nb.cells.append(
        nbformat.v4.new_markdown_cell(src) if kind == "md" else nbformat.v4.new_code_cell(src)
    )
nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
out = Path("notebooks/07_real_robot.ipynb")
NotebookClient(
    nb, timeout=1800, kernel_name="python3", resources={"metadata": {"path": "notebooks"}}
).execute()
nbformat.write(nb, out)
print("wrote", out)
