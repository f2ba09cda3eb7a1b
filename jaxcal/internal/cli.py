"""The command line's entry points for tests and benchmarks (`main(argv)` returns the
exit status instead of exiting). A submodule of its own so that `jaxcal.internal`, like
the rest of the library, never imports the command line."""

from .._cli.main import (
    COMMANDS as COMMANDS,
    build_parser as build_parser,
    fix_names as fix_names,
    main as main,
)
