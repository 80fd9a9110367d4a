"""The work behind each `vslam` command, as library functions: one module per command (run, odometry, loops,
train_loops, localize, horizon, graph, info). Each function takes paths and options, writes the command's files and
returns what it measured; the CLI in `vslam.cli` only parses arguments, calls one of them and prints."""
