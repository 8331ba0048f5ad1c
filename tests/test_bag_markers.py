"""The markers recorded in every bag of bags/ (make bags), read with mcap_ros2 (not the
project's reader): at every step one mesh per present block and one force segment per
interface vertex, stamped with the step's report, a step a second, in one fixed frame."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rbe_ros.io.replay import STEP_NS, read_runs

BAGS = sorted(p for p in (Path(__file__).resolve().parents[1] / "bags").iterdir() if p.is_dir())


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_markers_of_every_step(bag):
    [mcap] = bag.glob("*.mcap")
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        markers = {message.log_time: decoded for _, _, message, decoded
                   in reader.iter_decoded_messages(topics=["/rbe_node/markers"])}
    runs = read_runs(bag)
    assert sum(len(r.reports) for r in runs) == len(markers) > 0
    for run in runs:
        assert run.report_stamps == [run.stamp_ns + (k + 1) * STEP_NS
                                     for k in range(len(run.reports))]
        state_ids = {b["id"] for b in run.state["blocks"]}
        for report, stamp in zip(run.reports, run.report_stamps):
            array = markers[stamp].markers
            assert array[0].action == 3 and all(
                m.header.frame_id == report["header"]["frame_id"] == "world" for m in array)
            blocks = [m for m in array if m.ns == "blocks"]
            ids = [m.text for m in blocks]
            assert len(ids) == len(set(ids)) == report["num_blocks"]
            assert set(ids) <= state_ids
            if report["block_placed"]:
                assert report["block_placed"] in ids
            assert all(m.type == 11 and len(m.points) % 3 == 0 and m.points for m in blocks)
            forces = [m for m in array if m.ns == "forces"]
            starts = np.array([[p.x, p.y, p.z] for m in forces for p in m.points[0::2]])
            vertices = np.array([[p["x"], p["y"], p["z"]] for i in report["interfaces"]
                                 for p in i["polygon"]])
            assert len(starts) == len(vertices)
            if len(vertices):
                assert np.allclose(np.sort(starts, axis=0), np.sort(vertices, axis=0))
            [text] = [m for m in array if m.ns == "text"]
            assert text.text.endswith(report["message"])
