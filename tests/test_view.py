"""``rbe-ros view`` on every example, generator scene and bag: one self-contained page
whose rows are the reports (recorded, or the checker's own) and whose 3D data are the
blocks present at each step."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from rbe_ros.analysis.options import CheckOptions
from rbe_ros.cli import main
from rbe_ros.generators import GENERATORS
from rbe_ros.io.replay import read_runs, replay_run, Run
from rbe_ros.io.messages import state_to_dict
from rbe_ros.io.scene_json import load_scene

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((REPO / "examples").glob("*.json"))
BAGS = sorted(p for p in (REPO / "bags").iterdir() if p.is_dir())


def page_data(path: Path) -> dict:
    text = path.read_text()
    # self-contained: no script, style, image or link fetched from anywhere
    assert not re.search(r"""<(script|link|img|iframe)[^>]*\b(src|href)=""", text)
    assert "plotly" in text.lower() and len(text) > 4_000_000    # plotly.js inlined
    data = re.search(r'<script id="data" type="application/json">(.*?)</script>', text, re.S)
    return json.loads(data.group(1).replace("<\\/", "</"))


def check_rows(data: dict, runs: list[tuple[dict, list[dict]]]) -> None:
    """One row per report with its verdict and numbers; at each step the roles name exactly
    the blocks the report checked (num_blocks) and every block has a mesh."""
    rows = data["steps"]
    reports = [(k, r) for k, (_, rs) in enumerate(runs) for r in rs]
    assert len(rows) == len(reports) > 0
    for row, (k, report) in zip(rows, reports):
        assert row["run"] == k and row["step"] == report["step_index"]
        assert row["status"] == next(n for n, v in data["statuses"].items()
                                     if v == report["status"])
        assert row["message"] == report["message"]
        assert row["max_tension"] == pytest.approx(report["max_tension"])
        blocks = {b["id"]: b for b in data["runs"][k]["blocks"]}
        if report["status"] != data["statuses"]["INVALID_INPUT"]:
            assert len(row["roles"]) == report["num_blocks"]
        assert set(row["roles"]) <= set(blocks)
        assert all(len(blocks[b]["x"]) % 3 == 0 and blocks[b]["x"] for b in row["roles"])
        forces = sum(len(line["x"]) // 3 for line in row["lines"]
                     if line["name"].startswith("forces"))
        assert forces == sum(len(i["polygon"]) for i in report["interfaces"])
    # every colour of a line or arrow drawn is in the legend, and nothing else
    drawn = {c["colour"] for s in rows for c in (*s["lines"], *s["robot_arrows"],
                                                  *([s["arrow"]] if s["arrow"] else []))}
    assert {e["colour"] for e in data["line_legend"]} == drawn


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_view_of_every_bag(bag, tmp_path):
    out = tmp_path / "report.html"
    assert main(["view", str(bag), "-o", str(out)]) == 0
    check_rows(page_data(out), [(r.state, r.reports) for r in read_runs(bag)])


#: The 140-block dome's sequence, checked twice (the view, the independent replay), takes
#: minutes since the placement test's own-caps rule (open courses rub at their cones):
#: in make test-long.
SLOW_VIEWS = {"dome"}


@pytest.mark.parametrize("scene", [*EXAMPLES, *(pytest.param(g, marks=pytest.mark.long)
                                                if g in SLOW_VIEWS else g
                                                for g in sorted(GENERATORS))],
                         ids=[p.stem for p in EXAMPLES] + sorted(GENERATORS))
def test_view_of_every_example_and_generator(scene, tmp_path):
    if isinstance(scene, str):
        path = tmp_path / f"{scene}.json"
        assert main(["generate", scene, "-o", str(path)]) == 0
    else:
        path = scene
    out = tmp_path / "report.html"
    assert main(["view", str(path), "-o", str(out)]) == 0
    data = page_data(out)
    state = state_to_dict(load_scene(path), "world")
    reports = replay_run(Run(state, 0), CheckOptions())   # the node's answers, independently
    assert len(reports) == len(load_scene(path).sequence) > 0
    check_rows(data, [(state, reports)])
    assert data["options"]["solve"]["mu"] == 0.6


def test_view_shows_the_margin_where_known(tmp_path):
    out = tmp_path / "report.html"
    example = str(REPO / "examples" / "build_sequence.json")
    assert main(["view", example, "-o", str(out), "--margin"]) == 0
    rows = page_data(out)["steps"]
    state = state_to_dict(load_scene(example), "world")
    options = CheckOptions(margin_directions=8)
    reports = replay_run(Run(state, 0), options)
    assert [r["margin"] for r in rows] == pytest.approx(
        [None if r["margin_g"] < 0 else r["margin_g"] for r in reports])
    assert any(r["margin"] and r["margin"] > 0 for r in rows)
    assert rows[-1]["margin"] == 0.0                       # the cap tips: no margin
    assert main(["view", example, "-o", str(out)]) == 0
    assert {r["margin"] for r in page_data(out)["steps"]} == {None}   # not computed
