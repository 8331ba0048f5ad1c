"""A cell's long session, recorded and replayed: ``rbe-ros replay --compare`` against the
time the session took and the memory it may use (``make bench-replay``; docs/SESSIONS.md).

The session is synthetic, recorded through the core's bag writer as ``rbe_node`` records
one (same topics, types, QoS, settings, CDR): a design on ``/rbe_node/design``, then the
measured poses of every block placed so far on ``/rbe_node/poses`` at ``--rate`` Hz for
``--duration`` s of bag time, a block placed every so often (all of them by 80% of the
session; the rest of it the finished wall is watched), each pose the design's (a robot's
placement record: a pose does not change once placed). The node is simulated, not run: its
worker answers the newest waiting message when it is free and drops the others (the
single-slot buffer of :mod:`rbe_ros.ros.node`), and a check keeps it busy as long as the
check, its report dict and its markers take here (measured once per distinct as-built
scene; the node would spend that long on every repeat). The bag's stamps say ``--duration``
seconds; writing it takes only the checks' time. Reports and markers go in at the time the
simulated node publishes them.

Then ``rbe-ros replay BAG --compare`` runs in a subprocess: its wall time against the
recorded duration, its peak RSS (``getrusage`` of the child) and whether every recorded
report is reproduced.

Usage: .venv/bin/python benchmarks/replay_session.py [--courses 20 --bricks 15
--duration 600 --rate 10] [--out DIR] [--doc docs/SESSIONS.md]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbe_ros import generators  # noqa: E402
from rbe_ros.analysis.options import CheckOptions  # noqa: E402
from rbe_ros.io.bag import BagWriter  # noqa: E402
from rbe_ros.io.markers import MARKER_TOPIC, MARKER_TYPE, step_markers  # noqa: E402
from rbe_ros.io.messages import (poses_to_dict, report_header, report_to_dict,  # noqa: E402
                                scene_from_state_dict, state_to_dict)
from rbe_ros.io.poses import AsBuilt  # noqa: E402
from rbe_ros.io.replay import (DESIGN_TOPIC, OPTIONS_KEY, POSES_TOPIC, POSES_TYPE,  # noqa: E402
                               REPORT_TOPIC, REPORT_TYPE, SETTINGS_TYPE, STATE_TYPE,
                               asbuilt_check, options_to_json)

#: 2024-01-01T00:00:00Z, as the regression bags
STAMP0 = 1_704_067_200 * 1_000_000_000
SETTINGS_TOPIC = "/rbe_node/settings"
#: share of the session in which the blocks are placed (the rest: the finished wall)
PLACING = 0.8


class SimulatedNode:
    """rbe_node's state worker on a bag clock: one check at a time, the newest waiting
    message next, the others dropped (counted in ``dropped_states``)."""

    def __init__(self, bag: BagWriter, options: CheckOptions):
        self.bag, self.options = bag, options
        self.free_at = 0
        self.dropped = 0
        self.answered = 0
        self.distinct = 0
        self.busy_ns = 0
        self._last = None           # (scene, report dicts, marker dicts, busy ns)

    def answer(self, header: dict, scene, start_ns: int) -> None:
        if self._last is None or self._last[0] is not scene:
            began = time.perf_counter()
            result = asbuilt_check(scene, self.options)
            report = result.reports[0] if result.error is None else result.error
            data = report_to_dict(replace(report, dropped_states=self.dropped), header)
            markers = step_markers(result.scene, report, header)
            self._last = (scene, data, markers, int((time.perf_counter() - began) * 1e9))
            self.distinct += 1
        _, data, markers, busy = self._last
        done = start_ns + busy
        self.bag.write(REPORT_TOPIC, {**data, "header": header,
                                      "dropped_states": self.dropped}, done)
        self.bag.write(MARKER_TOPIC, markers, done)
        self.free_at = done
        self.answered += 1
        self.busy_ns += busy


def record_session(path, design, *, duration_s: float, rate_hz: float,
                   options: CheckOptions = CheckOptions()) -> dict:
    """Record the session bag at ``path`` (module docstring); what happened in it."""
    state = state_to_dict(design, "world", STAMP0)
    design = scene_from_state_dict(state)       # as the node reads it (meshes, block frames)
    order = list(design.sequence)
    poses = {b.id: ([float(v) for v in b.position], [float(v) for v in b.orientation])
             for b in design.blocks}
    count = int(duration_s * rate_hz)
    period = int(1e9 / rate_hz)
    place_every = max(1, int(count * PLACING / len(order)))
    settings = {"options": json.loads(options_to_json(options)), "frame_id": "world"}
    with BagWriter(path, custom_data={OPTIONS_KEY: options_to_json(options)}) as bag:
        bag.add_topic(REPORT_TOPIC, REPORT_TYPE, transient_local=True)
        bag.add_topic(MARKER_TOPIC, MARKER_TYPE, transient_local=True)
        bag.add_topic(SETTINGS_TOPIC, SETTINGS_TYPE, transient_local=True)
        bag.add_topic(DESIGN_TOPIC, STATE_TYPE, transient_local=True)
        bag.add_topic(POSES_TOPIC, POSES_TYPE)
        bag.write(SETTINGS_TOPIC, {"data": json.dumps(settings, sort_keys=True)}, STAMP0)
        node = SimulatedNode(bag, options)
        asbuilt = AsBuilt()
        bag.write(DESIGN_TOPIC, state, STAMP0)
        node.answer(report_header(state["header"]), asbuilt.set_design(design), STAMP0)
        slot = None
        for k in range(1, count + 1):
            stamp = STAMP0 + k * period
            if slot is not None and node.free_at <= stamp:
                node.answer(*slot, node.free_at)
                slot = None
            placed = order[:min(len(order), k // place_every)]
            message = poses_to_dict({i: poses[i] for i in placed}, "world", stamp)
            bag.write(POSES_TOPIC, message, stamp)
            waiting = (report_header(message["header"]), asbuilt.update(
                {i: poses[i] for i in placed}))
            if node.free_at <= stamp:
                node.answer(*waiting, stamp)
            else:
                node.dropped += slot is not None
                slot = waiting
        if slot is not None:
            node.answer(*slot, max(node.free_at, stamp))
    return {"messages": count + 1, "answered": node.answered, "distinct": node.distinct,
            "node_busy_s": node.busy_ns / 1e9,
            "dropped": node.dropped, "duration_s": duration_s, "rate_hz": rate_hz,
            "blocks": len(order), "bag_mb": sum(f.stat().st_size for f in
                                                 Path(path).glob("*.mcap")) / 1e6}


def replay(path, out) -> dict:
    """``rbe-ros replay --compare`` of the bag in a child process: time, peak RSS, result."""
    cli = Path(sys.executable).with_name("rbe-ros")
    began = time.perf_counter()
    proc = subprocess.run([str(cli), "replay", str(path), "--compare", "-o", str(out)],
                          capture_output=True, text=True)
    elapsed = time.perf_counter() - began
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"replay_s": elapsed, "replay_cpu_s": usage.ru_utime + usage.ru_stime,
            "peak_rss_mb": usage.ru_maxrss / 1024, "exit": proc.returncode,
            "stdout": proc.stdout.strip().splitlines()[-3:],
            "progress_lines": len(proc.stderr.strip().splitlines())}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--courses", type=int, default=20)
    parser.add_argument("--bricks", type=int, default=15, help="bricks per even course")
    parser.add_argument("--duration", type=float, default=600.0, help="bag time, s")
    parser.add_argument("--rate", type=float, default=10.0, help="poses messages per s")
    parser.add_argument("--out", help="directory for the bags (default: a temporary one)")
    parser.add_argument("--doc", help="write the figures into this markdown page")
    parser.add_argument("--reuse", action="store_true",
                        help="with --out: replay the session recorded there before, if any")
    args = parser.parse_args(argv)
    design = generators.running_bond_wall(courses=args.courses, bricks_per_course=args.bricks)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.out or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        bag = folder / f"session_{int(args.duration)}s"
        made = bag.with_name(bag.name + ".json")
        if args.reuse and made.is_file():
            session = json.loads(made.read_text())
        else:
            began = time.perf_counter()
            session = record_session(bag, design, duration_s=args.duration, rate_hz=args.rate)
            session["record_s"] = time.perf_counter() - began
            made.write_text(json.dumps(session))
        print(json.dumps(session), flush=True)
        out = folder / f"{bag.name}_replay"
        if out.exists():
            shutil.rmtree(out)
        result = {**session, **replay(bag, out)}
    result["load"] = os.getloadavg()
    result["ratio"] = result["replay_s"] / result["duration_s"]
    print(json.dumps(result, indent=1))
    if args.doc:
        write_doc(Path(args.doc), result, argv if argv is not None else sys.argv[1:])
    return 0 if result["exit"] == 0 else 1


def write_doc(path: Path, r: dict, argv: list[str]) -> None:
    """The measurement section of docs/SESSIONS.md (between its markers)."""
    table = "\n".join([
        "| | |", "| --- | --- |",
        f"| session (bag time) | {r['duration_s']:.0f} s, {r['rate_hz']:g} Hz ~/poses, "
        f"{r['messages']} messages, {r['blocks']} blocks placed |",
        f"| bag | {r['bag_mb']:.0f} MB |",
        f"| simulated node | {r['answered']} answered ({r['distinct']} distinct as-built "
        f"scenes), {r['dropped']} dropped |",
        f"| the simulated node's checks | {r['node_busy_s']:.0f} s busy (check, report, "
        f"markers; {r['record_s']:.0f} s to write the bag) |",
        f"| `rbe-ros replay --compare` | {r['replay_s']:.0f} s wall = {r['ratio']:.2f} x the "
        f"recorded duration; {r['replay_cpu_s']:.0f} s CPU; exit {r['exit']} |",
        f"| peak RSS of the replay | {r['peak_rss_mb']:.0f} MB |",
        f"| load (1, 5, 15 min) | {', '.join(f'{v:.1f}' for v in r['load'])} |",
        f"| replay's last lines | {'; '.join(r['stdout'])} |"])
    command = "`.venv/bin/python benchmarks/replay_session.py " + " ".join(argv) + "`"
    text = path.read_text()
    begin, end = "<!-- replay_session: begin -->", "<!-- replay_session: end -->"
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    path.write_text(f"{head}{begin}\n{command} (load measured at the end):\n\n{table}\n"
                    f"{end}{tail}")


if __name__ == "__main__":
    sys.exit(main())
