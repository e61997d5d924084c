"""The ``rolling-drive`` command line: ``main`` parses and dispatches, each subcommand lives
in a module of its own here."""
