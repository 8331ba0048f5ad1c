"""Command line of rbe_ros: check, tilt, min-friction, analyse and plan a scene JSON file,
replay a recorded bag.

Bad input gives one line ``rbe-ros: error: ...`` and exit status 2, never a traceback.
With ``--strict`` the exit status is 1 when a checked assembly or step is not stable.
"""
from __future__ import annotations

import argparse
import functools
import inspect
import json
import math
import shutil
import signal
import sys
import time
from pathlib import Path

from dataclasses import replace

from .analysis.asbuilt import declared
from .analysis.assembly import Assembly
from .analysis.friction import minimum_friction
from .analysis.grips import validate_cell
from .analysis.option_spec import BY_PATH, OPTIONS, from_outer
from .analysis.options import CheckOptions
from .analysis.planning import BACKUP_BLOCK_STATES, MIN_BACKUP, PREFER
from .analysis.cell_execution import CellPlan, repair_cell
from .analysis.repair import repair_plan
from .analysis.pipeline import check_scene, check_sequence, first_failing_step, slim
from .analysis.executors import CheckPool, ProcessPool, ray_checks, ray_cluster
from .analysis.perturb import PoseNoise
from .analysis.robust import RobustJob, estimate, sample_scene, serial
from .analysis.tilt import DIRECTIONS, tilt_capacity
from .analysis.timeline import busy_robots, recheck_timeline
from .analysis.validate import validated_assembly
from .analysis.verdict import check
from .analysis.virtual import ANALYSES, virtual_assembly
from .cell import cell_to_dict
from .generators import GENERATORS
from .interlock import INTERLOCK_GENERATORS
from .io import lmgc90
from .io.figures import draw_report
from .io.cell_file import parse_cell, read_cell
from .io.messages import (header_dict, json_safe, report_json, report_to_dict, state_to_dict,
                          timeline_to_dicts)
from .io.replay import (PLAN, REPORT_TOPIC, STATE_TOPIC, Run, RunReader, bag_options,
                        default_output, offline_reports, read_runs, replay_bag, step_stamps,
                        write_runs)
from .io.plan_export import plan_cell, plan_export, read_timeline
from .io.plan_output import (ProgressLines, ReportLines, repair_json, repair_text, step_summaries,
                              weakest_json, weakest_line, weakest_p_json,
                              weakest_p_line)
from .io.table import format_table
from .io.view import ViewRun, checked_runs, write_html
from .io.scene_json import load_scene, read_json, scene_to_dict
from .io.inputs import load_design
from .io.plans import PlanLimits, plan_state, robots_held
from .io.poses import load_poses, scene_at_poses
from .io.stored_interfaces import compare_interfaces
from .scene import Scene, SceneError

#: replay: at most one progress line on stderr per this many seconds
PROGRESS_S = 2.0


def _input_arguments(parser: argparse.ArgumentParser) -> None:
    i = parser.add_argument_group("input (the scene: a scene JSON or a COMPAS Assembly JSON, "
                                  "either gzipped as *.gz)")
    i.add_argument("--poses", metavar="POSES.json",
                   help='measured poses {"poses": {ID: {"position": [x, y, z], "orientation": '
                   '[x, y, z, w]}}}: the design\'s supports and the measured blocks at their '
                   'measured poses are checked; blocks not measured are not placed')
    i.add_argument("--density", type=float, default=None, metavar="KG_M3",
                   help="density of the blocks of a COMPAS file that gives them none "
                   "(default 2500)")
    i.add_argument("--supports", type=node_keys, default=None, metavar="KEY[,KEY...]",
                   help="the support blocks of a COMPAS file by node key, instead of its "
                   "is_support flags (for files whose supports a script sets)")
    i.add_argument("--interfaces", choices=("detected", "stored", "compare"),
                   default="detected", help="detected (default); stored: check on the "
                   "interfaces a COMPAS file stores, as given; compare: list how the detected "
                   "ones differ from the stored ones (missing, extra, area), then check on the "
                   "detected ones")


def _solver_arguments(parser: argparse.ArgumentParser, command: str = "") -> None:
    """The input arguments and every check option of :data:`OPTIONS` with a flag (for
    ``command``)."""
    _input_arguments(parser)
    groups = {"contact": parser.add_argument_group(
                  "contact detection (lengths relative to the smaller block's size, the cube "
                  "root of its volume)"),
              "holds": parser.add_argument_group("suggested holds (unstable checks)")}
    model = parser.add_argument_group("RBE model")
    for option in OPTIONS:
        if option.flag is None or option.commands and command not in option.commands:
            continue
        group = groups.get(option.path.split(".")[0], model)
        if option.kind is bool:     # on by default: the flag turns it off
            group.add_argument(option.flag, dest=option.path, help=option.help,
                               action="store_false" if option.default else "store_true")
            continue
        metavar = option.metavar or option.flag.lstrip("-").upper().replace("-", "_")
        group.add_argument(option.flag, dest=option.path, type=option.kind,
                           default=option.default, choices=option.choices or None,
                           metavar=None if option.choices else metavar,
                           help=option.help if option.kind is str
                           else f"{option.help} (default {option.default:g})")
    groups["contact"].add_argument(
        "--pose-uncertainty", type=uncertainty, default=None, metavar="POS_M[,ANGLE_DEG]",
        help="both --pose-uncertainty-m and --pose-uncertainty-deg at once (README: Checking "
        "as-built poses; default: the scene's \"pose_uncertainty\", else design geometry)")


def uncertainty(text: str) -> tuple[float, float]:
    """POS_M[,ANGLE_DEG] (argparse type: ValueError for anything else)."""
    parts = [float(x) for x in text.split(",")]
    if not 1 <= len(parts) <= 2 or not all(math.isfinite(x) and x >= 0 for x in parts):
        raise ValueError(text)
    return parts[0], parts[1] if len(parts) > 1 else 0.0


def node_keys(text: str) -> tuple[str, ...]:
    """KEY[,KEY...] (argparse type): node keys, none of them empty."""
    keys = tuple(k.strip() for k in text.split(","))
    if not all(keys):
        raise ValueError(text)
    return keys


def _min_margin_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--min-margin", type=float, default=0.0, metavar="G",
                        help="a step whose stability margin (share of g, as check --margin) is "
                        "below G does not stand (default 0: off)")


def _executor_arguments(parser: argparse.ArgumentParser, what: str, ray_more: str) -> None:
    """--workers and --ray: where ``what`` runs."""
    parser.add_argument("--workers", type=int, default=1, metavar="K",
                        help=f"local worker processes for {what} (default 1: this process)")
    parser.add_argument("--ray", metavar="ADDRESS",
                        help=f"run {what} as Ray tasks on the cluster at ADDRESS ('auto': "
                        f"the local cluster's{ray_more})")


def _options(args) -> CheckOptions:
    """The check options of the flags (ValueError naming a flag out of its range)."""
    values = {o: getattr(args, o.path) for o in OPTIONS
              if o.flag is not None and hasattr(args, o.path)}
    if args.pose_uncertainty is not None:
        m, deg = BY_PATH["contact.pose_uncertainty_m"], BY_PATH["contact.pose_uncertainty_deg"]
        values[m], values[deg] = args.pose_uncertainty
    return from_outer(values)


def _scene(args) -> tuple[Scene, Assembly | None]:
    """The scene of ``args.scene`` (``--poses`` applied) and, with ``--interfaces stored``,
    its assembly on the stored interfaces (else None: detected in the check). With
    ``--interfaces compare`` the differences are printed first (to stderr after --json)."""
    if args.poses and args.interfaces != "detected":
        raise ValueError("--interfaces stored and compare are of the blocks as the file has "
                         "them, not at measured poses (--poses)")
    scene, stored = load_design(args.scene, args.density, stored=args.interfaces != "detected",
                                supports=args.supports)
    args.warnings = _warn(scene)            # what loading repaired: --json lists them too
    if args.poses:
        scene = scene_at_poses(scene, load_poses(args.poses))
    if args.interfaces == "compare":
        diff = compare_interfaces(Assembly.from_scene(
            scene, declared(_options(args), scene).contact), stored)
        args.interfaces_compare = diff
        as_json = getattr(args, "json", False)
        if not (as_json and args.command == "check"):
            print("\n".join(diff.lines()), file=sys.stderr if as_json else sys.stdout)
        stored = None
    return scene, stored


def _warn(scene: Scene) -> list[str]:
    """Print what loading ``scene`` repaired (one line each on stderr); the warnings."""
    for warning in scene.warnings:
        print(f"rbe-ros: warning: {warning}", file=sys.stderr)
    return list(scene.warnings)


def _assembly(args) -> Assembly:
    """The validated assembly of ``args.scene`` (the limits of the options; SceneError)."""
    scene, stored = _scene(args)
    options = declared(_options(args), scene)
    return validated_assembly(scene, options.limits, options.contact, stored)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every rbe-ros command and its options."""
    parser = argparse.ArgumentParser(prog="rbe-ros", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="check an assembly, or every step of its sequence")
    check.add_argument("scene", help="scene JSON file (format in README)")
    check.add_argument("--sequence", action="store_true",
                       help="check every insertion step of the scene's sequence")
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.add_argument("--bag", metavar="DIR",
                       help="record states and reports as a rosbag2 MCAP bag in DIR")
    check.add_argument("--force", action="store_true", help="replace an existing --bag DIR")
    check.add_argument("--no-markers", action="store_true",
                       help="--bag without the markers of the reports (a lean log)")
    check.add_argument("--strict", action="store_true",
                       help="exit 1 when an assembly or step is not stable")
    check.add_argument("--timeline", action="store_true",
                       help="re-check every state of the timeline of a plan written by "
                            "plan --cell CELL -o FILE (the states made from its actions)")
    _solver_arguments(check, "check")
    check.set_defaults(run=_run_check)

    tilt = sub.add_parser("tilt", help="largest tilt of gravity the assembly stands")
    tilt.add_argument("scene")
    tilt.add_argument("--direction", choices=DIRECTIONS, default="x",
                      help="where the horizontal part of the turned gravity points")
    tilt.add_argument("--tol-deg", type=float, default=0.01, help="bisection tolerance")
    tilt.add_argument("--json", action="store_true")
    _solver_arguments(tilt)
    tilt.set_defaults(run=_run_tilt)

    fric = sub.add_parser("min-friction", help="smallest mu at which the assembly stands")
    fric.add_argument("scene")
    fric.add_argument("--tol", type=float, default=1e-4)
    fric.add_argument("--json", action="store_true")
    _solver_arguments(fric)
    fric.set_defaults(run=_run_min_friction)

    analyse = sub.add_parser("analyse", help="check on virtual (reduced) interfaces")
    analyse.add_argument("scene")
    analyse.add_argument("--analysis", choices=ANALYSES, default="kern-fitting")
    analyse.add_argument("--factor", type=float, default=0.1,
                         help="shrink factor of base-fitting and max-thrust")
    analyse.add_argument("--json", action="store_true")
    _solver_arguments(analyse)
    analyse.set_defaults(run=_run_analyse)

    figure = sub.add_parser("figure", help="draw the forces of a check (or an analysis) as PNG")
    figure.add_argument("scene")
    figure.add_argument("-o", "--output", required=True, help="PNG file to write")
    figure.add_argument("--analysis", choices=ANALYSES, default=None)
    figure.add_argument("--factor", type=float, default=0.1)
    figure.add_argument("--view", type=float, nargs=2, default=(20.0, -60.0),
                        metavar=("ELEV", "AZIM"), help="camera elevation and azimuth in deg")
    _solver_arguments(figure)
    figure.set_defaults(run=_run_figure)

    generate = sub.add_parser("generate", help="write a parametric scene as JSON")
    generate.add_argument("name", choices=sorted({**GENERATORS, **INTERLOCK_GENERATORS}))
    generate.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE",
                          help="generator parameter (JSON value), e.g. -p n=15 "
                          "-p thickness_ratio=0.12")
    generate.add_argument("-o", "--output", required=True, help="scene JSON file to write")
    generate.set_defaults(run=_run_generate)

    plan = sub.add_parser("plan", help="find an insertion order in which every step stands "
                          "with at most K held blocks")
    plan.add_argument("scene")
    plan.add_argument("--cell", metavar="CELL",
                      help="plan for the robots of a cell file (JSON or YAML; see README): a "
                           "timeline of their actions, every state between them checked")
    plan.add_argument("--max-held", type=int, metavar="K",
                      help="blocks that may be held (by robots or scaffolds) at any step")
    plan.add_argument("--beam", type=int, default=1, metavar="W",
                      help="partial plans kept per step (default 1: greedy)")
    plan.add_argument("--candidates", type=int, default=0, metavar="N",
                      help="candidates tried per partial plan and step, lowest first (default "
                      "0: all; a limit makes an exhausted search no proof that no plan exists)")
    plan.add_argument("--search-budget", type=int, default=0, metavar="N",
                      help="states the search may check before it gives up (a state: a "
                      "partial plan and the block it places); default 0: the first descent "
                      f"(the greedy plan), then max({MIN_BACKUP}, {BACKUP_BLOCK_STATES} / the "
                      "blocks to place) more")
    plan.add_argument("--keep-sequence", action="store_true",
                      help="the scene's sequence is a fixed prefix of the order")
    plan.add_argument("--prefer", choices=PREFER, default="holds",
                      help="which feasible candidate a step keeps: holds (default: fewest "
                      "hold-steps, the first that fits) or margin (of the first --candidates, "
                      "the largest weakest margin so far, then fewest hold-steps)")
    plan.add_argument("--robust", type=int, default=0, metavar="N",
                      help="with --prefer margin: rank candidates by p_stable, the share of N "
                      "samples of the declared pose uncertainty (about 3 sigma, as robust "
                      "--pose-sigma a third of it, seed 0) in which the step stands, then by "
                      "margin; needs --prefer margin and a declared uncertainty (default 0: "
                      "by margin)")
    _min_margin_argument(plan)
    plan.add_argument("-o", "--output", metavar="SCENE",
                      help="write the planned scene (sequence and holds) as JSON")
    plan.add_argument("--json", action="store_true", help="print one JSON object: the plan "
                      "and one summary per step (status, holds, margin, worst ratio, time)")
    plan.add_argument("--reports", metavar="FILE.jsonl",
                      help="write every step's full report as JSON Lines, as it is made")
    _executor_arguments(plan, "the full checks of the steps ahead (the plan is the same)",
                        "; 'local': a new local instance of --workers CPUs")
    plan.add_argument("--full-candidates", action="store_true",
                      help="check every candidate trial whole (without the incremental "
                      "checks, to compare with)")
    _solver_arguments(plan)
    plan.set_defaults(run=_run_plan)

    repair = sub.add_parser("repair", help="repair the rest of a plan from measured poses of "
                            "the blocks placed so far (README: Building from measurements)")
    repair.add_argument("scene", metavar="PLANNED.json",
                        help="the plan: a planned scene (rbe-ros plan -o), sequence and holds")
    repair.add_argument("--json", action="store_true", help="print one JSON object")
    repair.add_argument("-o", "--output", metavar="REPAIRED.json",
                        help="write the repaired plan (the placed blocks at their measured "
                        "poses) as a scene file; check it with check --sequence")
    repair.add_argument("--max-held", type=int, default=None, metavar="K",
                        help="blocks that may be held at a step (default: the plan's largest "
                        "number held at a step)")
    _min_margin_argument(repair)
    repair.add_argument("--no-replan", action="store_true",
                        help="hold and swap repairs only, no re-planning of the remainder")
    repair.add_argument("--lookahead-steps", type=int, default=0, metavar="N",
                        help="check and repair only the next N steps (a node's look-ahead "
                        "window; default 0: every remaining step)")
    repair.add_argument("--workers", type=int, default=1, metavar="K",
                        help="local worker processes that check the remaining steps whole, "
                        "queued ahead (default 1: this process); the same verdicts")
    _solver_arguments(repair)
    repair.set_defaults(run=_run_repair)

    robust = sub.add_parser("robust", help="probability that the assembly (or each step) "
                            "stands under Gaussian placement error (Monte Carlo)")
    robust.add_argument("scene")
    robust.add_argument("--pose-sigma", type=uncertainty, required=True,
                        metavar="POS_M[,ANGLE_DEG]",
                        help="standard deviation of each free block's position per axis (m) "
                        "and of its rotation about a random axis (deg); samples are checked "
                        "with the pose uncertainty declared at 3 sigma")
    robust.add_argument("--samples", type=int, default=400, metavar="N")
    robust.add_argument("--seed", type=int, default=0, metavar="S",
                        help="sample k is drawn from the seed (S, k): same numbers whatever "
                        "the executor")
    robust.add_argument("--sequence", action="store_true",
                        help="p_stable of every step too (a sample's step k is its partial "
                        "assembly)")
    robust.add_argument("--json", action="store_true", help="print one JSON object")
    robust.add_argument("-o", "--output", metavar="WORST.json",
                        help="write the failing sample closest to the design as a scene file")
    _executor_arguments(robust, "the batches", "; README: How sure is a step?")
    robust.add_argument("--batch", type=int, default=16, metavar="B",
                        help="samples per task (default 16)")
    _solver_arguments(robust)
    robust.set_defaults(run=_run_robust)

    view = sub.add_parser("view", help="write one self-contained HTML report of a scene's "
                          "check or of a bag: 3D view, step slider, table of steps, options")
    view.add_argument("scene", metavar="SCENE|BAG", help="a scene file (checked here, every "
                      "step when it has a sequence) or a rosbag2 bag (directory or .mcap: its "
                      "states and reports as recorded, with its options)")
    view.add_argument("-o", "--output", required=True, help="HTML file to write")
    view.add_argument("--sequence", action="store_true",
                      help="a scene without a sequence: check every block in file order")
    _solver_arguments(view)
    view.set_defaults(run=_run_view)

    replay = sub.add_parser("replay", help="re-check the states of a bag, write a bag of the "
                            "new reports and compare them with the recorded ones")
    replay.add_argument("bag", help="rosbag2 MCAP bag directory (or .mcap file)")
    replay.add_argument("--compare", action="store_true",
                        help="compare with the recorded reports; exit 1 on a difference")
    replay.add_argument("--live", action="store_true",
                        help="replay through an rbe_node (started here unless --node-name)")
    replay.add_argument("--node-name", metavar="NAME",
                        help="with --live: use the running node NAME (e.g. rbe_node)")
    replay.add_argument("-o", "--output", metavar="DIR",
                        help="bag to write (default: BAG_replay; never overwritten)")
    replay.add_argument("--no-markers", action="store_true",
                        help="write the new bag without the markers of the reports")
    replay.add_argument("--timeout", type=float, default=120.0, metavar="S",
                        help="--live: seconds to wait for each answer (default 120)")
    replay.set_defaults(run=_run_replay)
    return parser


def _run_check(args) -> int:
    if args.timeline:
        return _run_check_timeline(args)
    scene, stored = _scene(args)
    options = declared(_options(args), scene)      # recorded in the bag as checked
    if options.second_opinion != "none":
        lmgc90.installed_python()       # not installed: one line before any work
    if args.bag:
        _prepare_bag_dir(Path(args.bag), args.force)
    if stored is not None and (args.sequence or args.bag):
        raise ValueError("--interfaces stored checks the assembly as a whole, and is not "
                         "recorded (a replay detects the interfaces): no --sequence or --bag")
    if args.sequence:
        def progress(report, total: int) -> None:
            if report.step_index == 0:      # after validation: bad input gives one line only
                print(f"checking {scene.name}: {len(scene.blocks)} blocks, {total} steps",
                      file=sys.stderr)
            _progress(report, total)

        # the table needs no interfaces: kept, they would grow with the steps squared
        reports = check_sequence(scene, options, on_step=None if args.json else progress,
                                 keep=None if args.json or args.bag else slim)
        out = {"scene": scene.name, "first_failing_step": first_failing_step(reports),
               "reports": [report_json(r) for r in reports]}
    else:
        reports = [check_scene(scene, options, stored)]
        out = {"scene": scene.name, **report_json(reports[0])}
    out["warnings"] = args.warnings
    if args.interfaces == "compare":
        out["interfaces_compare"] = args.interfaces_compare.to_json()
    opinions = lmgc90.second_opinions(
        scene, reports, options, args.sequence,
        on_state=lambda k, n: print(f"second opinion ({options.second_opinion}): state {k + 1}"
                                    f" of {n}", file=sys.stderr, flush=True))
    for report, opinion in zip(out["reports"] if args.sequence else [out], opinions):
        report["second_opinion"] = opinion
    if args.bag:
        _record(Path(args.bag), scene, reports, options, args.sequence, not args.no_markers)
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(format_table(reports))
        for report, opinion in zip(reports, opinions):
            step = f"step {report.step_index}: " if args.sequence else ""
            print(step + lmgc90.describe(opinion, report.solve_time, report.status.name))
        if args.bag:
            print(f"bag written to {args.bag}")
    return 1 if args.strict and not all(r.stable for r in reports) else 0


def _run_tilt(args) -> int:
    result = tilt_capacity(_assembly(args), _options(args),
                           args.direction, args.tol_deg)
    out = json_safe({"direction": result.direction, "tilt_deg": result.tilt_deg,
                     "multiplier": result.multiplier,
                     "tilt_deg_multiplier": result.tilt_deg_multiplier,
                     "bisection_trials": result.trials, "time_bisection": result.time_bisection,
                     "time_multiplier": result.time_multiplier})
    if args.json:
        print(json.dumps(out, indent=1))
    elif math.isnan(result.tilt_deg):
        print("the assembly does not stand untilted: no tilt capacity (see rbe-ros check)")
    else:
        print(f"tilt capacity towards {result.direction}: {result.tilt_deg:.2f} deg by bisection"
              f" ({result.trials} solves), lambda = {result.multiplier:.4f}"
              f" (atan: {result.tilt_deg_multiplier:.2f} deg) by one load-multiplier solve")
    return 0


def _run_min_friction(args) -> int:
    mu = minimum_friction(_assembly(args), _options(args), args.tol)
    if args.json:
        print(json.dumps(json_safe({"mu_min": mu})))
    else:
        print(f"minimum friction coefficient: {mu:.4f}" if math.isfinite(mu)
              else "no friction coefficient makes the assembly stand (it needs tension, or a"
                   " squeeze that blocks set one at a time without pre-load never get)")
    return 0


def _analysed(args):
    """The assembly of ``args.scene`` (on virtual interfaces if ``args.analysis``) and its check."""
    assembly = _assembly(args)
    if args.analysis:
        assembly = virtual_assembly(assembly, args.analysis, args.factor)
    return assembly, check(assembly, _options(args))


def _run_analyse(args) -> int:
    _, report = _analysed(args)
    if args.json:
        print(json.dumps({"analysis": args.analysis, **report_json(report)}, indent=1))
    else:
        print(f"{args.analysis}: {report.message}")
    return 0


def _run_figure(args) -> int:
    assembly, report = _analysed(args)
    title = f"{args.analysis + ': ' if args.analysis else ''}{report.message}"
    path = draw_report(assembly, report, args.output, title=title, view=tuple(args.view))
    print(f"figure written to {path}")
    return 0


def _run_generate(args) -> int:
    make = {**GENERATORS, **INTERLOCK_GENERATORS}[args.name]
    allowed = inspect.signature(make).parameters
    params = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or key not in allowed:
            raise ValueError(f"{args.name} takes -p KEY=VALUE with KEY one of {', '.join(allowed)};"
                             f" got {item!r}")
        try:
            params[key] = json.loads(value)
        except json.JSONDecodeError:
            params[key] = value
    try:
        scene = make(**params)
    except TypeError as exc:      # a parameter of the wrong kind, e.g. n=abc
        raise ValueError(f"{args.name}: {exc}") from None
    path = Path(args.output)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(scene_to_dict(scene)))
    print(f"{scene.name}: {len(scene.blocks)} blocks written to {path}")
    return 0


def _run_robust(args) -> int:
    if args.samples < 1 or args.batch < 1:
        raise ValueError("--samples and --batch must be at least 1")
    scene = load_scene(args.scene)
    _warn(scene)
    job = RobustJob(scene, PoseNoise(*args.pose_sigma), args.seed, _options(args), args.sequence)
    pool = ProcessPool(args.workers) if args.workers > 1 and not args.ray else None
    executor = ray_cluster(args.ray) if args.ray else pool or serial

    def progress(done: int, total: int) -> None:
        if not args.json:
            print(f"  {done}/{total} samples", file=sys.stderr)

    try:
        result = estimate(job, args.samples, executor, args.batch, progress)
    finally:
        if pool is not None:
            pool.close()
    out = {"scene": scene.name, "pose_sigma": list(args.pose_sigma), "seed": args.seed,
           "p_stable": result.p_stable, "interval": list(result.interval),
           "samples": result.samples, "closest_failing_sample": result.closest_failure}
    if args.sequence:
        out["steps"] = result.steps
    if args.output and result.closest_failure is not None:
        worst = sample_scene(job, result.closest_failure)
        Path(args.output).write_text(json.dumps(scene_to_dict(worst)))
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    lo, hi = result.interval
    print(f"p_stable {result.p_stable:.3f} (95% {lo:.3f} .. {hi:.3f}) over {result.samples} "
          f"samples, seed {args.seed}")
    for s in result.steps:
        print(f"  step {s['step']:>3}  {s['block'] or '-':<20} p_stable {s['p_stable']:.3f}"
              f"  ({s['interval'][0]:.3f} .. {s['interval'][1]:.3f})")
    if args.output:
        print(f"closest failing sample ({result.closest_failure}) written to {args.output}"
              if result.closest_failure is not None else "no sample failed: nothing written")
    return 0


def _progress(report, total: int) -> None:
    print(f"  step {report.step_index + 1}/{total}: {report.block_placed} {report.status.name}",
          file=sys.stderr)


def _prepare_bag_dir(path: Path, force: bool) -> None:
    if path.exists():
        if not force:
            raise SceneError(f"bag directory {str(path)!r} exists (use --force to replace it)")
        shutil.rmtree(path)
    path.parent.mkdir(parents=True, exist_ok=True)


def _record(path: Path, scene: Scene, reports, options: CheckOptions, sequence: bool,
            markers: bool) -> None:
    """Write the scene's state and every report (and with ``markers`` its markers), as the
    node would have published them, a step a second, and the options (so that ``rbe-ros
    replay`` re-checks the same way). The state holds the order checked (``sequence``) or no
    sequence (a check as a whole)."""
    order = (scene.sequence or tuple(b.id for b in scene.blocks if not b.support)) \
        if sequence else ()
    stamp = time.time_ns()
    header = header_dict("world", stamp)
    run = Run(state_to_dict(replace(scene, sequence=order), "world", stamp), stamp,
              STATE_TOPIC, [report_to_dict(r, header) for r in reports],
              step_stamps(stamp, len(reports)), REPORT_TOPIC)
    write_runs(path, [run], [run.reports], options, markers=markers)


def _run_check_timeline(args) -> int:
    """``check --timeline``: every state of an exported timeline re-checked."""
    if args.sequence or args.bag:
        raise ValueError("--timeline checks the states of the file's timeline: no --sequence "
                         "or --bag")
    scene, _ = _scene(args)
    data, _ = read_json(args.scene)
    cell, actions = read_timeline(data)
    options = declared(_options(args), scene)
    reports = recheck_timeline(cell, scene, actions, options)
    rows = [{"action": a.action, "robot": a.robot, "block": a.block, "step": a.step,
             "busy": busy, "stable": r.stable, "status": r.status.name, "recorded": a.stable,
             "message": r.message} for a, r, busy in zip(actions, reports, busy_robots(actions))]
    stable = all(r.stable for r in reports)
    if args.json:
        print(json.dumps({"scene": scene.name, "robots": list(cell.names), "stable": stable,
                          "states": len(rows), "timeline": rows}, indent=1))
    else:
        for row in rows:
            print(f"{row['step']:4d} {row['action']:8s} {row['robot']:10s} {row['block']:20s} "
                  f"busy {row['busy']}  {row['status']}"
                  + ("" if row["stable"] else f": {row['message']}"))
        print(f"timeline: {len(rows)} states, {'every one stable' if stable else 'NOT all stable'}")
    return 1 if args.strict and not stable else 0


def _cell_limits(args, scene: Scene) -> tuple[str, int]:
    """The cell text and the held blocks of ``plan`` (errors of the command line: exit 2)."""
    if args.cell is None:
        if args.max_held is None:
            raise ValueError("plan needs --max-held K or --cell CELL")
        return "", args.max_held
    cell = read_cell(args.cell)
    validate_cell(cell, scene)
    return json.dumps(cell_to_dict(cell)), robots_held(cell, args.max_held or 0)


def _run_plan(args) -> int:
    options = _options(args)
    scene, stored = _scene(args)
    if stored is not None:
        raise ValueError("plan detects the interfaces of every partial assembly (not "
                         "--interfaces stored)")
    cell, args.max_held = _cell_limits(args, scene)
    if not args.json:
        print(f"planning {scene.name}: {sum(not b.support for b in scene.blocks)} blocks to "
              f"place, at most {args.max_held} held", file=sys.stderr)
    if args.workers < 1:
        raise ValueError("--workers must be at least 1")
    if args.search_budget < 0:
        raise ValueError(f"--search-budget must be >= 0 (0: the default), not "
                         f"{args.search_budget}")
    look_ahead = (ray_checks(None if args.ray == "local" else args.ray, max(args.workers, 2),
                             **({"num_cpus": args.workers} if args.ray == "local" else {}))
                  if args.ray else
                  functools.partial(CheckPool, workers=args.workers) if args.workers > 1
                  else None)
    # the plan's --time-limit bounds the whole search, not each check
    limit = options.solve.time_limit
    limits = PlanLimits(args.max_held, args.beam, args.candidates, args.keep_sequence,
                        time_limit=limit if math.isfinite(limit) else 0.0,
                        search_budget=args.search_budget, cell=cell, prefer=args.prefer,
                        min_margin=args.min_margin, robust_samples=args.robust)
    limits.search()                 # a limit out of range: an error of the command line
    if args.robust < 0:
        raise ValueError(f"--robust must be >= 0 (0: off), not {args.robust}")
    if args.robust and not declared(options, scene).contact.uncertain:
        raise ValueError("--robust N samples the declared pose uncertainty: declare one "
                         "(--pose-uncertainty-m / --pose-uncertainty-deg, or the scene's "
                         "pose_uncertainty)")
    options = replace(options, solve=replace(options.solve, time_limit=math.inf))
    reports = ReportLines(args.reports) if args.reports else None
    interrupted = []
    previous = signal.signal(signal.SIGINT, lambda *_: interrupted.append(True))
    try:
        plan = plan_state(lambda: scene, limits, options, progress=ProgressLines(sys.stderr),
                          should_stop=lambda: bool(interrupted), on_report=reports,
                          look_ahead=look_ahead, full_candidates=args.full_candidates)
    finally:
        signal.signal(signal.SIGINT, previous)
        if reports is not None:
            reports.close()
    if args.output and plan.scene is not None:
        out_path = Path(args.output)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_text(json.dumps(json_safe(plan_export(plan, options))))
    if args.json:
        out = {"scene": scene.name, "feasible": plan.feasible, "outcome": plan.outcome,
               "max_held": args.max_held,
               "order": plan.order, "failed_step": plan.failed_step, "message": plan.message,
               "failure": plan.failure, "search_states": plan.states,
               "search_backups": plan.backups,
               "holds": scene_to_dict(plan.scene).get("holds", []) if plan.scene else [],
               "search_checks": plan.checks, "models": plan.models, "time": plan.time,
               "prefer": args.prefer, "min_margin": args.min_margin, "robust": args.robust,
               "weakest_step": weakest_json(plan.weakest),
               "weakest_p_stable": weakest_p_json(plan),
               "steps": step_summaries(plan), "warnings": args.warnings}
        if plan.timeline is not None:
            out["robots"] = list(plan.timeline.robots)
            out["timeline"] = json_safe(timeline_to_dicts(plan.timeline, header_dict("world", 0)))
        print(json.dumps(out, indent=1))
    else:
        verdict = "feasible" if plan.feasible else f"NOT feasible (step {plan.failed_step})"
        print(f"plan: {verdict}: {plan.message}")
        print(f"order: {', '.join(plan.order)}")
        print(weakest_line(plan.weakest))
        if plan.p_stable:
            print(weakest_p_line(plan, args.robust))
        if plan.reports:
            print(format_table(plan.reports))
        if plan.timeline is not None:
            actions = plan.timeline.actions
            falls = sum(not a.stable for a in actions)
            print(f"timeline: {len(actions)} actions of {', '.join(plan.timeline.robots)}, "
                  f"at most {max(busy_robots(actions), default=0)} busy, "
                  + (f"{falls} states fall" if falls else "every state stands"))
        if args.output and plan.scene is not None:
            print(f"planned scene written to {args.output}")
    return 0 if plan.feasible else 1


def _view_run(k: int, run: Run) -> ViewRun:
    """The view of a bag's run: a plan for a cell with its robots and timeline."""
    view = ViewRun(f"run {k}", *run.checked())
    timeline = run.reports[0].get("timeline") if run.kind == PLAN and run.reports else None
    if timeline and str(run.state.get("cell", "")).strip():
        view = replace(view, cell=parse_cell(run.state["cell"]), timeline=timeline)
    return view


def _run_repair(args) -> int:
    if not args.poses:
        raise ValueError("repair needs --poses MEASURED.json: the poses of the blocks placed")
    if args.interfaces != "detected":
        raise ValueError("repair detects the interfaces at the measured poses (not "
                         "--interfaces stored or compare)")
    options = _options(args)
    plan, _ = load_design(args.scene, args.density, supports=args.supports)
    built = scene_at_poses(plan, load_poses(args.poses))
    limit = options.solve.time_limit
    options = replace(options, solve=replace(options.solve, time_limit=math.inf))
    if args.min_margin < 0:
        raise ValueError(f"--min-margin must be >= 0, not {args.min_margin:g}")
    if args.workers < 1:
        raise ValueError("--workers must be at least 1")
    cell = plan_cell(args.scene)        # a plan for a cell: repaired within it
    timeline = None
    if cell is None:
        result = repair_plan(plan, built, options, max_held=args.max_held,
                             min_margin_g=args.min_margin, time_limit=limit,
                             replan=not args.no_replan, lookahead_steps=args.lookahead_steps,
                             workers=args.workers if args.workers > 1 else 0)
    else:
        result, timeline = repair_cell(plan, built, options, CellPlan(cell, plan, options),
                                       min_margin_g=args.min_margin,
                                       lookahead_steps=args.lookahead_steps,
                                       max_held=args.max_held, replan=not args.no_replan,
                                       time_limit=limit)
    extra = {} if timeline is None else {
        "cell": cell_to_dict(cell),
        "timeline": json_safe(timeline_to_dicts(timeline, header_dict("world", 0)))}
    if args.output and result.scene is not None:
        out_path = Path(args.output)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_text(json.dumps({**scene_to_dict(result.scene), **extra}))
    if args.json:
        print(json.dumps({**repair_json(result), **extra}, indent=1))
    else:
        print(repair_text(result))
        if args.output:
            print(f"repaired plan written to {args.output}" if result.scene is not None
                  else "no repaired plan: nothing written")
    return 0 if result.feasible else 1


def _run_view(args) -> int:
    source = Path(args.scene)
    if source.suffix == ".mcap" or (source / "metadata.yaml").is_file():
        options = bag_options(source)
        runs = [_view_run(k, run) for k, run in enumerate(read_runs(source))]
        title = source.name
    else:
        options = _options(args)
        scene, _ = _scene(args)
        order = scene.sequence or tuple(b.id for b in scene.blocks if not b.support)
        steps = args.sequence or bool(scene.sequence)
        state = state_to_dict(replace(scene, sequence=order if steps else ()), "world")
        runs = checked_runs([(scene.name, state)], options)
        data, _ = read_json(source)
        if isinstance(data, dict) and "timeline" in data:     # a plan for a cell (plan -o)
            cell, _ = read_timeline(data)
            runs = [replace(runs[0], cell=cell, timeline=data["timeline"])]
        title = scene.name
    if not runs:
        raise ValueError(f"{source}: no states to show")
    path = write_html(args.output, runs, options, title)
    print(f"{sum(len(r.reports) for r in runs)} reports of {len(runs)} states written to {path}")
    return 0


def _run_replay(args) -> int:
    if args.node_name and not args.live:
        raise ValueError("--node-name needs --live")
    out = Path(args.output) if args.output else default_output(args.bag)
    if out.exists():
        raise FileExistsError(f"output {str(out)!r} exists already, not overwriting it "
                              "(give another -o)")

    started = time.monotonic()
    shown = [started]

    def progress(i: int, run) -> None:
        """A line on stderr at most every PROGRESS_S (a session bag has thousands of runs)."""
        now = time.monotonic()
        if now - shown[0] >= PROGRESS_S or i == 0:
            shown[0] = now
            total = f"/{runs.total}" if runs.total else ""
            print(f"  run {i + 1}{total} ({now - started:.0f} s): {run.describe()}: "
                  f"{len(run.reports)} recorded reports", file=sys.stderr)

    recheck = offline_reports
    if args.live:
        # rclpy is loaded only for --live: every other command runs without ROS
        from .ros.live import live_recheck
        recheck = live_recheck(args.node_name, timeout=args.timeout)
    runs = RunReader(args.bag)
    try:
        result = replay_bag(runs, out, compare=args.compare, recheck=recheck,
                            markers=not args.no_markers, on_run=progress, keep=False)
    except RuntimeError as exc:     # the live node failed or exited
        raise ValueError(str(exc)) from None
    executed = f", {result.executed} plan execution messages" if result.executed else ""
    print(f"replayed {result.states} states ({result.reports} reports{executed}"
          f"{', live' if args.live else ''}) in {time.monotonic() - started:.1f} s; bag "
          f"written to {result.output}")
    if result.orphan_reports:
        print(f"{result.orphan_reports} recorded reports answer states not in this bag (a "
              "file of a split bag: replay the bag directory): not compared")
    if not args.compare:
        return 0
    if result.matches:
        print("all recorded reports reproduced (within the tolerances)")
        return 0
    print(f"MISMATCH: {result.difference_count} field(s) differ from the recorded reports:")
    print(result.diff())
    return 1


def main(argv=None) -> int:
    """Run one command; bad input is one line on stderr and exit status 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (SceneError, ValueError, OSError, lmgc90.NotInstalled) as exc:
        print(f"rbe-ros: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
