"""``vbn`` subcommands contributed by visibility_builder (see ``landmark_db.cli.main``)."""
