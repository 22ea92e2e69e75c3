"""``vbn`` subcommands contributed by landmark_localizer (see ``landmark_db.cli.main``)."""
