"""``rbe-ros plan --prefer margin --robust N`` (issue 30): candidates ranked by p_stable over N
samples of the declared pose uncertainty, then by margin. On a ledge scene the two rankings
disagree (a plate near a ledge's edge has the larger margin, a column the larger p_stable);
each step's p_stable is checked by ``rbe-ros robust --sequence`` of the planned scene (the
same samples), and the plate's against the closed form P(its centroid stays on the ledge)."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from rbe_ros import generators
from rbe_ros.analysis import planning
from rbe_ros.analysis.margin import report_margin
from rbe_ros.analysis.planning import PlanOptions, _Planner, plan_sequence
from rbe_ros.cli import main
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.scene import SceneError

from helpers import LEDGE_INSIDE as INSIDE, LEDGE_SIGMA as SIGMA, ledge

SAMPLES = 16


def run(capsys, *argv) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_p_stable_ranks_where_margin_ranks_otherwise(tmp_path, capsys):
    scene = tmp_path / "ledge.json"
    scene.write_text(json.dumps(scene_to_dict(ledge())))
    code, out, _ = run(capsys, "plan", scene, "--max-held", "0", "--prefer", "margin", "--json")
    by_margin = json.loads(out)
    assert code == 0 and by_margin["order"] == ["plate", "column"]     # 0.2 g first
    assert [s["margin_g"] for s in by_margin["steps"]] == pytest.approx([0.2, 0.125], abs=1e-6)
    assert "p_stable" not in by_margin["steps"][0]
    assert by_margin["weakest_p_stable"]["step"] == -1
    planned = tmp_path / "planned.json"
    code, out, _ = run(capsys, "plan", scene, "--max-held", "0", "--prefer", "margin",
                       "--robust", SAMPLES, "--json", "-o", planned)
    robust = json.loads(out)
    assert code == 0 and robust["order"] == ["column", "plate"] and robust["robust"] == SAMPLES
    p = [s["p_stable"] for s in robust["steps"]]
    assert p[0] == 1.0 and p[1] < 1.0
    assert robust["weakest_p_stable"] == {"step": 1, "block": "plate", "p_stable": p[1],
                                          "margin_g": pytest.approx(0.125, abs=1e-6)}
    # the oracle: robust --sequence of the planned scene, the same samples (seed 0)
    code, out, _ = run(capsys, "robust", planned, "--pose-sigma", SIGMA, "--samples", SAMPLES,
                       "--sequence", "--json")
    steps = json.loads(out)["steps"]
    assert [s["p_stable"] for s in steps] == p
    # and the closed form: the plate stands while its centroid stays on the ledge
    lo, hi = steps[1]["interval"]
    assert lo <= 0.5 * (1 + math.erf(INSIDE / SIGMA / math.sqrt(2))) <= hi
    code, out, _ = run(capsys, "plan", scene, "--max-held", "0", "--prefer", "margin",
                       "--robust", 4)
    assert "weakest step by p_stable: " in out and "over 4 samples" in out


def test_robust_needs_prefer_margin_and_a_declared_uncertainty(tmp_path, capsys):
    with pytest.raises(ValueError, match="only prefer margin does"):
        PlanOptions(robust=4)
    scene = tmp_path / "ledge.json"
    scene.write_text(json.dumps(scene_to_dict(ledge())))
    code, out, err = run(capsys, "plan", scene, "--max-held", "0", "--robust", "4")
    assert code == 2 and out == "" and "only prefer margin does" in err
    design = tmp_path / "design.json"
    design.write_text(json.dumps(scene_to_dict(ledge(None))))
    code, _, err = run(capsys, "plan", design, "--max-held", "0", "--prefer", "margin",
                       "--robust", "4")
    assert code == 2 and "declare one" in err
    with pytest.raises(SceneError, match="robust 4: p_stable samples the declared pose"):
        plan_sequence(ledge(None), 0, prefer="margin", robust=4)


def eager(self, partial, failure):
    """The ranking before the lazy one: every feasible child tried and scored, then sorted
    (its weakest p_stable so far, its weakest margin so far, then the default's score)."""
    children = []
    for child, found in self.feasible(partial, failure):
        found = self.with_margin(found)
        child.reports = (*partial.reports, replace(
            child.reports[-1], margin_g=found.report.margin_g,
            margin_direction=found.report.margin_direction))
        parts = []
        if self.samples is not None:
            child.p_stable = (*partial.p_stable, self.samples.p_stable(
                self.present(child.order, len(child.order) - 1), found.held))
            parts.append(-min(child.p_stable))
        parts.append(-min(r.margin_g for r in child.reports))
        child.score = (*parts, *child.score[-3:])
        children.append(child)
    return iter(sorted(children, key=lambda c: (c.score, c.order)))


@pytest.mark.parametrize("robust", [0, pytest.param(8, marks=pytest.mark.long)])
def test_lazy_ranking_returns_the_plan_of_scoring_every_child(monkeypatch, robust):
    """The 7-voussoir arch with a declared uncertainty: the lazy ranking's plan is that of
    trying and scoring every child (by margin, and by p_stable then margin), with fewer
    margins made."""
    arch = replace(generators.semicircular_arch(n=7), pose_uncertainty=(0.006, 1.5))
    margins = []
    monkeypatch.setattr(planning, "report_margin",
                        lambda *a: margins.append(1) or report_margin(*a))
    lazy = plan_sequence(arch, 2, prefer="margin", robust=robust)
    made, margins[:] = len(margins), []
    monkeypatch.setattr(_Planner, "_best_first", eager)
    full = plan_sequence(arch, 2, prefer="margin", robust=robust)
    assert lazy.feasible and full.feasible
    assert (lazy.order, lazy.held, lazy.p_stable) == (full.order, full.held, full.p_stable)
    assert [r.margin_g for r in lazy.reports] == [r.margin_g for r in full.reports]
    assert lazy.checks <= full.checks and lazy.states <= full.states
    assert made < len(margins)


def test_lazy_margin_ranking_keeps_the_plan_of_before():
    """The 7-voussoir arch's plan --prefer margin as it was before the lazy ranking."""
    plan = plan_sequence(generators.semicircular_arch(n=7), 2, prefer="margin", candidates=8)
    assert plan.order == ["v00", "v01", "v02", "v03", "v04", "v06", "v05"]
    assert plan.held == [(), ("v01",), ("v02",), ("v03",), ("v04",), ("v04",), ()]
    assert plan.weakest.margin_g == pytest.approx(0.125451, abs=1e-5)
