"""`vslam horizon`: 1D SURF horizon landmarks - memorise, recognise, score pairs, evaluate.

    vslam horizon memorise IMAGES... --row R --out MEM.npz       store landmarks (one per image)
    vslam horizon recognise MEM.npz IMAGE... --row R              which stored landmark each image shows
    vslam horizon pairs PAIRS.csv --out SCORES.csv                score image pairs (columns a,b,row_a,row_b)
    vslam horizon evaluate SCORES.csv --plot ROC.png              ROC / AUC of scored pairs with a label column

A horizon is a row number, or LEFT:RIGHT for a horizon line crossing the left image edge at row LEFT and the right
edge at row RIGHT (a rolled camera). Relative image paths in a CSV are relative to the CSV's folder.
"""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "horizon"
HELP = "1D SURF horizon landmarks: memorise, recognise, score pairs, evaluate"
DESCRIPTION = __doc__


def _memorise(args: argparse.Namespace) -> int:
    from vslam.app.horizon import memorise  # imported on use: keeps `vslam --help` fast (see vslam.cli.main)

    memory = memorise(args.images, args.row, args.out, args.names, args.append, args.preset, args.overrides,
                      echo=print)
    print(f"wrote {args.out} ({len(memory)} landmarks)")
    return 0


def _recognise(args: argparse.Namespace) -> int:
    from vslam.app.horizon import recognise

    recognise(args.memory, args.images, args.row, args.threshold, args.json, echo=print)
    return 0


def _pairs(args: argparse.Namespace) -> int:
    from vslam.app.horizon import score_pairs

    rows = score_pairs(args.pairs, args.out, args.preset, args.overrides)
    print(f"wrote {args.out} ({len(rows)} pairs)")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from vslam.app.horizon import evaluate_scores

    evaluate_scores(args.scores, args.label_column, args.max_fpr, args.plot, echo=print)
    return 0


def _add_params_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default=None,
                   help="HorizonParams preset: fast (default; every band, packed scoring), paper, robust, bands")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a HorizonParams field, e.g. --set threshold=20 (repeatable)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter  # keep the usage block of the description
    sub = parser.add_subparsers(dest="horizon_command", metavar="ACTION")
    sub.required = True

    p = sub.add_parser("memorise", help="extract and store landmarks (one per image) in a memory file")
    p.add_argument("images", nargs="+", type=Path, help="images to memorise")
    p.add_argument("--row", required=True, help="horizon row (or LEFT:RIGHT) in every image")
    p.add_argument("--out", type=Path, required=True, help="memory file to write (.npz)")
    p.add_argument("--names", nargs="+", help="landmark names (default: image file stems)")
    p.add_argument("--append", action="store_true", help="add to an existing memory instead of replacing it")
    _add_params_args(p)
    p.set_defaults(func=_memorise)

    p = sub.add_parser("recognise", help="which stored landmark (if any) each image shows")
    p.add_argument("memory", type=Path, help="memory file written by `vslam horizon memorise`")
    p.add_argument("images", nargs="+", type=Path, help="images to recognise")
    p.add_argument("--row", required=True, help="horizon row (or LEFT:RIGHT) in every image")
    p.add_argument("--threshold", type=float, default=None,
                   help="NN+RANSAC score needed to recognise (default: the memory's recognition_threshold)")
    p.add_argument("--json", type=Path, help="also write the results as JSON")
    p.set_defaults(func=_recognise)

    p = sub.add_parser("pairs", help="score image pairs: PAIRS.csv (a,b,row_a,row_b) -> SCORES.csv")
    p.add_argument("pairs", type=Path, help="CSV with columns a,b,row_a,row_b (other columns are copied)")
    p.add_argument("--out", type=Path, required=True,
                   help="CSV to write: the input columns + score,score_ransac,b_s,b_d")
    _add_params_args(p)
    p.set_defaults(func=_pairs)

    p = sub.add_parser("evaluate", help="ROC / AUC of a SCORES.csv that has a 0/1 label column")
    p.add_argument("scores", type=Path, help="CSV written by `vslam horizon pairs`")
    p.add_argument("--label-column", default="label", help="column with 1 = same landmark (default: %(default)s)")
    p.add_argument("--max-fpr", type=float, default=0.05, help="report the best sensitivity at this false "
                   "positive rate (default: %(default)s)")
    p.add_argument("--plot", type=Path, help="write the ROC curve as a PNG")
    p.set_defaults(func=_evaluate)


def run(args: argparse.Namespace) -> int:  # pragma: no cover - argparse dispatches to the action
    return args.func(args)

