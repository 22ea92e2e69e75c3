"""``vbn`` subcommands contributed by vbn_worlds (see ``vbn_common.cli.main``)."""
