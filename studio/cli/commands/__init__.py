"""One module per ``studio`` sub-command (discovered by :func:`studio.cli.build_parser`)."""
