"""A cell's long sessions: bags split by size and duration (each file complete, the carried
messages at its start, the files read in split order) and a streamed replay whose memory
does not grow with the session."""
from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rbe_ros import generators
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.cli import PROGRESS_S, main
from rbe_ros.io.bag import BagWriter, mcap_files, read_bag, to_dict, typestore
from rbe_ros.io.cdr import encoder
from rbe_ros.geometry.block import pose_block
from rbe_ros.io.messages import (header_dict, poses_to_dict, report_to_dict,
                                 scene_from_state_dict, state_to_dict)
from rbe_ros.io.replay import (DESIGN_TOPIC, POSES_TOPIC, POSES_TYPE, REPORT_TYPE, STATE_TYPE,
                               RunReader, replay_bag, report_repeats)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from replay_session import record_session  # noqa: E402

STRING = "std_msgs/msg/String"


def text(i: int) -> dict:
    """A message that compresses little (the file sizes are compressed sizes)."""
    return {"data": f"message {i:03d} " + hashlib.sha256(str(i).encode()).hexdigest() * 4}


def test_split_by_size_numbers_the_files_and_carries_the_latched_messages(tmp_path):
    bag = tmp_path / "cell"
    with BagWriter(bag, max_bytes=1500) as writer:
        writer.add_topic("/settings", STRING, transient_local=True)
        writer.add_topic("/data", STRING)
        writer.write("/settings", {"data": "settings 1"}, 0)
        writer.carry("/settings", {"data": "settings 1"})
        for i in range(60):
            writer.write("/data", text(i), (i + 1) * 1000)
            if i == 30:
                writer.write("/settings", {"data": "settings 2"}, (i + 1) * 1000)
                writer.carry("/settings", lambda: {"data": "settings 2"})
    files = mcap_files(bag)
    # x_0 ... x_10 ...: in split order, not in the order of the names' characters
    assert [f.name for f in files] == [f"cell_{k}.mcap" for k in range(len(files))]
    assert len(files) > 10
    data = []
    for k, f in enumerate(files):
        alone = [m.data["data"] for m in read_bag(f)]
        if k < len(files) - 1:      # split once the limit was reached
            assert f.stat().st_size >= 1500
        if k:       # every later file begins with the settings in force when it began
            first_data = next(int(t.split()[1]) for t in alone if t.startswith("message"))
            assert alone[0] == ("settings 2" if first_data > 31 else "settings 1")
        data += [int(t.split()[1]) for t in alone if t.startswith("message")]
    assert data == list(range(60))                  # every message once, in order
    whole = [m.data["data"] for m in read_bag(bag)]
    assert [t for t in whole if t.startswith("message")] == [t["data"] for t in map(text,
                                                                                  range(60))]
    meta = (bag / "metadata.yaml").read_text()
    assert all(f.name in meta for f in files)


def test_split_by_duration_starts_a_file_per_span(tmp_path):
    bag = tmp_path / "timed"
    with BagWriter(bag, max_duration_ns=10_000_000_000) as writer:    # 10 s
        writer.add_topic("/data", STRING)
        for i in range(35):                                           # one a second
            writer.write("/data", text(i), i * 1_000_000_000)
    spans = [[m.stamp_ns // 1_000_000_000 for m in read_bag(f)] for f in mcap_files(bag)]
    assert spans == [list(range(0, 10)), list(range(10, 20)), list(range(20, 30)),
                     list(range(30, 35))]
    with pytest.raises(ValueError, match="split"):
        BagWriter(tmp_path / "bad", max_bytes=-1)


def peak_rss_replay(bag: Path, out: Path, keep: bool = False) -> tuple[float, dict]:
    """A replay with comparison in a child process: its own peak RSS (MB) and counts
    (``keep``: holding every run and report, as replay did before it streamed)."""
    code = ("import json, resource, sys\n"
            "from rbe_ros.io.replay import replay_bag\n"
            f"r = replay_bag({str(bag)!r}, {str(out)!r}, keep={keep!r})\n"
            "print(json.dumps({'rss': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,"
            " 'states': r.states, 'reports': r.reports, 'recorded': r.recorded,"
            " 'differences': r.difference_count}))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    return result["rss"] / 1024, result


def test_replay_memory_does_not_grow_with_the_session(tmp_path):
    """A session three times as long (three times the reports) replays in the same peak
    memory, every recorded report reproduced. Holding the runs and reports (``keep``, as
    replay did before) grows the peak by about 14 MB here (21 MB from 10 s to 40 s)."""
    wall = generators.running_bond_wall(courses=3, bricks_per_course=3)
    runs = {}
    for seconds in (10, 30):
        bag = tmp_path / f"s{seconds}"
        made = record_session(bag, wall, duration_s=seconds, rate_hz=10)
        runs[seconds] = (made, *peak_rss_replay(bag, tmp_path / f"s{seconds}_replay"))
    for made, _, result in runs.values():
        assert result["states"] == made["messages"]
        assert result["recorded"] == result["reports"] == made["answered"]
        assert result["differences"] == 0
    assert runs[30][0]["answered"] >= 3 * runs[10][0]["answered"] - 5
    growth = runs[30][1] - runs[10][1]
    assert growth < 6, f"peak RSS {runs[10][1]:.0f} MB -> {runs[30][1]:.0f} MB"


def test_the_streamed_runs_are_the_recorded_ones(tmp_path):
    """RunReader hands on each run with its reports (matched by header stamp), the as-built
    scene after it, and reads the bag's reports once."""
    wall = generators.running_bond_wall(courses=2, bricks_per_course=2)
    made = record_session(tmp_path / "s", wall, duration_s=3, rate_hz=10)
    runs = list(RunReader(tmp_path / "s"))
    assert len(runs) == made["messages"]
    reports = [m.data for m in read_bag(tmp_path / "s", {REPORT_TYPE})]
    assert [r for run in runs for r in run.reports] == reports
    for run in runs:
        assert all(r["header"]["stamp"] == run.state["header"]["stamp"] for r in run.reports)
        placed = len(run.state.get("ids", []))
        assert sum(not b.support for b in run.asbuilt.blocks) == placed
    result = replay_bag(tmp_path / "s", write=False)
    assert result.matches and result.reports == len(reports)


def test_a_repeated_report_is_patched_and_read_as_the_full_codec_does():
    """A report that repeats the last but for stamp, solve_time and dropped_states: its CDR
    patched equals the full encoding, and read back equals rosbags' full decoding; any
    other change is read in full."""
    store = typestore()
    full = encoder(store, REPORT_TYPE)
    report = report_to_dict(check_scene(generators.running_bond_wall(3, 3)),
                            header_dict("world", 5))

    def decoded(raw: bytes) -> dict:
        return to_dict(store, REPORT_TYPE, store.deserialize_cdr(raw, REPORT_TYPE))

    writer, reader = report_repeats(), report_repeats()
    first = writer.encode(report)
    assert first == full(report)
    reader.learn(decoded(first), first)
    again = {**report, "header": header_dict("world", 7_000_000_123), "solve_time": 0.25,
             "dropped_states": 9}
    raw = writer.encode(again)
    assert raw == full(again)
    assert reader.decode(raw) == decoded(raw)
    assert reader.decode(raw)["dropped_states"] == 9
    for changed in ({**again, "margin_g": 0.5}, {**again, "message": report["message"] + "!"},
                    {**again, "header": header_dict("cell", 7)}):
        assert reader.decode(full(changed)) is None
        assert writer.encode(changed) == full(changed)


def test_the_same_poses_after_a_new_design_are_merged_into_it(tmp_path):
    """Poses that repeat the last ones but follow a new design (which forgets what was
    measured) are merged again, into the new design: not the scene of before."""
    short = generators.running_bond_wall(1, 2, brick=(0.4, 0.2, 0.1))
    long = generators.running_bond_wall(1, 2, brick=(0.6, 0.2, 0.1))
    poses = {b.id: ([float(v) for v in b.position], [float(v) for v in b.orientation])
             for b in scene_from_state_dict(state_to_dict(short)).blocks if not b.support}
    with BagWriter(tmp_path / "b") as bag:
        bag.add_topic(DESIGN_TOPIC, STATE_TYPE, transient_local=True)
        bag.add_topic(POSES_TOPIC, POSES_TYPE)
        bag.write(DESIGN_TOPIC, state_to_dict(short, "world", 1), 1)
        bag.write(POSES_TOPIC, poses_to_dict(poses, "world", 2), 2)
        bag.write(DESIGN_TOPIC, state_to_dict(long, "world", 3), 3)
        bag.write(POSES_TOPIC, poses_to_dict(poses, "world", 4), 4)
    runs = list(RunReader(tmp_path / "b"))
    assert [r.kind for r in runs] == ["design", "poses", "design", "poses"]
    volume = {k: sum(pose_block(b).volume for b in runs[k].asbuilt.blocks if not b.support)
              for k in (1, 3)}
    assert volume[1] == pytest.approx(2 * 0.4 * 0.2 * 0.1)
    assert volume[3] == pytest.approx(2 * 0.6 * 0.2 * 0.1)


def test_cli_replay_shows_progress_and_reproduces_a_session(tmp_path, capsys):
    """`rbe-ros replay --compare` of a session: a few progress lines on stderr (at most one
    per PROGRESS_S, not one per message), every recorded report reproduced."""
    made = record_session(tmp_path / "s", generators.running_bond_wall(2, 2), duration_s=10,
                          rate_hz=10)
    began = time.monotonic()
    code = main(["replay", str(tmp_path / "s"), "--compare", "-o", str(tmp_path / "o")])
    elapsed = time.monotonic() - began
    out, err = capsys.readouterr()
    assert code == 0, out
    assert f"replayed {made['messages']} states ({made['answered']} reports" in out
    assert "all recorded reports reproduced" in out
    lines = [line for line in err.splitlines() if line]
    assert lines[0].startswith(f"  run 1/{made['messages']} ")
    assert len(lines) <= 1 + elapsed / PROGRESS_S
