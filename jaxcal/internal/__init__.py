"""Names that tests, benchmarks and notebooks need but that are not part of the stable
public API (as `lineax.internal`): they may change between versions."""

from .._cache import cache_info as cache_info, clear_cache as clear_cache
from .._ident_result import make_result as make_result
