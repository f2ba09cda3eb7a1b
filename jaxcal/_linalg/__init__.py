"""Small dense linear algebra without LAPACK custom calls, as lineax solvers (see
`dense.py` for why)."""
