"""The discrepancy workflow: where simulation and measurement disagree, which candidate
effect explains it, and the model with that effect added (`discover`)."""

from ._discover import (
    CandidateResult as CandidateResult,
    DiscoveryReport as DiscoveryReport,
    discover as discover,
    discover_batch as discover_batch,
)
from ._supermodel import (
    SuperModel as SuperModel,
)
from ._tree import (
    TreeCandidate as TreeCandidate,
    TreeDiscovery as TreeDiscovery,
    TreeEffect as TreeEffect,
    discover_tree as discover_tree,
    tree_candidates as tree_candidates,
)
