"""``vbn`` subcommands contributed by visibility_builder (see ``vbn_common.cli.main``)."""
