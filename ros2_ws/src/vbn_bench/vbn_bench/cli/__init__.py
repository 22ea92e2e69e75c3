"""``vbn`` subcommands contributed by vbn_bench (see ``vbn_common.cli.main``)."""
