"""The ``vbn`` command line: a dispatcher plus one thin module per subcommand."""
