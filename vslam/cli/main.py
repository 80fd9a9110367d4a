"""The `vslam` command line.

Every sub-command lives in its own module `vslam/cli/cmd_<name>.py` exposing

    NAME: str                      # the sub-command, e.g. "simulate"
    HELP: str                      # one line for `vslam --help`
    def add_arguments(parser)      # fill an argparse parser
    def run(args) -> int           # do the work, return the exit code

Modules are discovered, so adding a command never touches this file. A command module only parses arguments,
calls one library function (most live in `vslam.app`) and prints. It imports that function inside `run`: every
command module is imported to build `vslam --help`, and the library pulls in gtsam, rerun and matplotlib, so a
top-level import would make `vslam --help` several times slower.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import signal
import sys
import threading
import warnings
from types import ModuleType

import vslam.cli as cli_package
from odometry.shared.errors import ToolkitError

# Errors a user can cause with bad input: reported as one clear line, no traceback. ToolkitError is the common base
# of the package roots (OdometryError, LoopsError, GraphError, VslamError) and of the shared layer's errors; any
# other exception is a bug and keeps its traceback.
USER_ERRORS = (ToolkitError, OSError)


def _command_modules() -> list[ModuleType]:
    names = sorted(m.name for m in pkgutil.iter_modules(cli_package.__path__) if m.name.startswith("cmd_"))
    return [importlib.import_module(f"vslam.cli.{n}") for n in names]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vslam",
        description="Visual SLAM with loop closure for ground robots (downward camera, compact-descriptor loops, GTSAM).",
    )
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        mod.add_arguments(p)
        if p.get_default("func") is None:
            p.set_defaults(func=mod.run)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that the same clean-up runs (no half-written recording or output)."""


def _terminate(signum, frame) -> None:
    raise Terminated()


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.command_line = list(sys.argv[1:] if argv is None else argv)   # how the run was asked for (bench docs)
    # warnings (skipped frames, decoder complaints naming the file, evaluation problems) as one line each
    previous_show = warnings.showwarning
    warnings.showwarning = lambda message, category, *_a, **_k: print(
        f"vslam {args.command}: warning: {message}", file=sys.stderr)
    in_main = threading.current_thread() is threading.main_thread()   # signal handlers live in the main thread
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main else None
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # output piped into `head` and closed: not an error
        return 0
    except Terminated:
        print("vslam: terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print("vslam: interrupted", file=sys.stderr)
        return 130
    except USER_ERRORS as exc:
        if args.debug:
            raise
        print(f"vslam {args.command}: error: {exc}", file=sys.stderr)
        return 2
    finally:
        warnings.showwarning = previous_show
        if in_main:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
