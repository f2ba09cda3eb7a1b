"""Monte-Carlo noise studies: vectorised trials of any identification method over a
design, chunked and sharded over devices, with per-parameter statistics, noise sweeps
and plots."""

from ._plots import (
    plot_error_vs_noise as plot_error_vs_noise,
    plot_histograms as plot_histograms,
)
from ._processes import (
    join_processes as join_processes,
    run_local_processes as run_local_processes,
)
from ._stats import (
    MonteCarloResult as MonteCarloResult,
)
from ._study import (
    monte_carlo as monte_carlo,
    trial_noise as trial_noise,
)
from ._sweeps import (
    load_sweep as load_sweep,
    noise_sweep as noise_sweep,
)
from ._tree import (
    TREE_METHODS as TREE_METHODS,
    TreeStudy as TreeStudy,
    tree_study as tree_study,
)
