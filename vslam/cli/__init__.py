"""Command-line interface; see `vslam.cli.main`."""
