"""The `radarcl` subcommands, one module each: ``SUMMARY`` (one line for `radarcl --help`),
``DESCRIPTION``, ``add_arguments(parser)`` (the command's own options) and ``run(args)`` (the
exit status). Each takes the parsed options and calls a library or job module; errors are
raised as ``RadarclError`` and turned into one sentence by ``radarcl.cli``. ``options`` holds
what several commands share."""
