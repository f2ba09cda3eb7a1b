"""The `jaxcal` command line: `main` and one module per command. Nothing in the library
imports this package."""

from .main import main as main
