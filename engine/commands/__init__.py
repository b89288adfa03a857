"""One module per subcommand of ``buildingparser`` (see :mod:`engine.cli`)."""
