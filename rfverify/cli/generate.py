"""``rfverify generate``: FCLIB problem collections from the scenes of :mod:`rfverify.scenes`."""

from __future__ import annotations

import argparse
import sys

from .argtypes import nonneg_int, out_path, positive_int, scene_name
from .common import exit_codes, EXIT_OK, dumps


def add_parser(sub) -> None:
    """The ``generate`` subcommand."""
    from ..scenes import ALL_SCENES, DEFAULT_STEPS

    gen = sub.add_parser(
        "generate", help="generate FCLIB problem collections from rigid-body and finite-element scenes",
        description="Build a rigid-body scene by a fast geometric method, take a few "
                    "Moreau-Jean steps (theta = 1, velocity level) from each stage of its run and "
                    "write the one-step problems as FCLIB HDF5 files SCENE-ndof-M-nc-N-K.hdf5 "
                    "(K = index in the trace). GranularBed, for large problems (1e4-1e5 contacts in "
                    "seconds, e.g. --size 3375: 9675 contacts), takes no step: its problem is the "
                    "first step's, built from the lattice without any solve, so its files do not "
                    "depend on the solver.\n\n"
                    "Reproducibility: the files are bit-for-bit the same for the same scene, seed\n"
                    "and options, run with the same rfverify and the same numpy, scipy and QDLDL\n"
                    "builds on one platform (thread counts and PYTHONHASHSEED do not matter). What\n"
                    "varies and why: the scene's motion is simulated with rfverify's own solver\n"
                    "(each step's contact problem is solved by rfverify.solve), and granular motion\n"
                    "amplifies small differences, so a change to the solver or to numpy/scipy/QDLDL\n"
                    "that changes any result, even in its last bit, changes the later positions and\n"
                    "contacts: the values, and which contacts (hence the nonzeros of H) a problem has.\n\n"
                    "scenes:\n" + "\n".join(f"  {k}: {v.summary}" for k, v in ALL_SCENES.items()),
        epilog=exit_codes("the files were written (or --list printed)"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    gen.add_argument("scene", metavar="SCENE", nargs="?", type=scene_name,
                     help="scene name (case-insensitive): " + ", ".join(ALL_SCENES))
    gen.add_argument("--list", action="store_true",
                     help="list the scenes with their default size and parameters, then exit")
    gen.add_argument("--count", type=positive_int, default=1, metavar="N",
                     help="problems in the trace (at most 10000); problem K comes from stage K/(N-1) of the run "
                          "(default: %(default)s)")
    gen.add_argument("--seed", type=nonneg_int, default=0, metavar="S",
                     help="random seed (default: %(default)s)")
    gen.add_argument("--size", type=positive_int, default=None, metavar="K",
                     help="bodies at the last stage (default: the scene's published size, "
                          "e.g. 250 for SpheresPile; use e.g. 20 for quick small instances)")
    gen.add_argument("--steps", type=positive_int, default=DEFAULT_STEPS, metavar="J",
                     help="Moreau-Jean steps per stage; the last is dumped (default: %(default)s; "
                          "not used by GranularBed)")
    gen.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                     help="override a numeric scene parameter (repeatable; see --list); a value outside "
                          "its domain (a fraction above 1, a tilt of 90 degrees or more, a count that is not "
                          "whole) is refused with exit 2")
    gen.add_argument("--out", metavar="DIR", type=out_path,
                     help="directory for the HDF5 files (created if missing); required "
                          "unless --list")
    gen.add_argument("--quiet", action="store_true",
                     help="no progress on stderr (otherwise a redrawn bar on a terminal, one line per "
                          "completed tenth when stderr is not a terminal; --json also silences it)")
    gen.add_argument("--json", action="store_true",
                     help="print one JSON object describing the written files")
    gen.set_defaults(func=cmd_generate, check_outputs=check_outputs)


def check_outputs(args) -> None:
    """Refuse an unusable --out DIR before any work."""
    from ..io.output import check_output_dir

    if args.out is not None and not args.list:
        check_output_dir(args.out)


def cmd_generate(args) -> int:
    import time

    from ..progress import Progress
    from ..scenes import ALL_SCENES, generate, save_collection, scene_parameters
    from ..scenes.stepper import SceneError

    if args.list:
        for name, sc in ALL_SCENES.items():
            print(f"{name} (default size {sc.default_size} {sc.size_unit}): {sc.summary}")
            print("    parameters: " + ", ".join(f"{k}={v:g}" for k, v in sc.defaults.items()))
        return EXIT_OK
    if args.scene is None or args.out is None:
        raise SceneError("generate needs SCENE and --out DIR (or --list)")
    params = {}
    for item in args.param:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise SceneError(f"--param {item!r}: expected KEY=VALUE; fix: give --param NAME=NUMBER "
                             "(rfverify generate --list gives each scene's parameters)")
        params[key.strip()] = val.strip()
    scene_parameters(args.scene, args.size, **params)  # bad names/values fail before any work
    bar = Progress(100, f"generate {args.scene}", quiet=args.quiet or args.json, percent=True)
    t0 = time.perf_counter()
    try:
        problems = generate(args.scene, count=args.count, seed=args.seed, size=args.size,
                            steps=args.steps, progress=bar.update_fraction, **params)
    finally:
        bar.close()
    paths = save_collection(problems, args.out)
    wall = time.perf_counter() - t0
    files = []
    for path, prob in zip(paths, problems):
        pv = prob.provenance
        files.append({"path": str(path), "m": prob.n_dofs, "n": prob.n_contacts,
                      "trace_index": pv["trace_index"], "failed_solves": pv["failed_solves"],
                      "solves": [s["status"] for s in pv["solves"]]})
        if pv["failed_solves"]:
            print(f"rfverify generate: warning: {path.name}: {pv['failed_solves']} of "
                  f"{len(pv['solves'])} step solve(s) did not reach the tolerance "
                  f"({', '.join(s['status'] for s in pv['solves'])}); advanced with the best "
                  "iterate (recorded in info/description)", file=sys.stderr)
    if args.json:
        print(dumps({"scene": args.scene, "seed": args.seed, "count": args.count,
                     "size": problems[0].provenance["size"], "time": wall, "files": files},
                    indent=2))
    else:
        for f in files:
            print(f"{f['path']}  m = {f['m']}, n = {f['n']}")
        print(f"{len(files)} problem(s) of {args.scene} written to {args.out} in {wall:.1f} s")
    return EXIT_OK
