"""check --second-opinion lmgc90: LMGC90 (non-smooth contact dynamics, in its own venv) checks
the same state beside ours. Not installed: one line saying how to install it, exit 2, no
traceback, before any work. Installed (make lmgc90): its verdict on a scene whose answer is
known by a closed form (a bar between two free pillars, no pre-load: it falls; a lintel on
them stands), the block that moved, and where it disagrees with ours."""
import json
from pathlib import Path

import pytest

from rbe_ros.cli import main
from rbe_ros.io import lmgc90

SUITE = Path(__file__).resolve().parent / "data" / "squeeze"


def test_not_installed_is_one_line_with_how_to_install(tmp_path, monkeypatch, capsys):
    missing = tmp_path / "no-venv"
    monkeypatch.setenv(lmgc90.VENV_ENV, str(missing))
    code = main(["check", str(SUITE / "pillars_mu0.60.json"), "--second-opinion", "lmgc90"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"rbe-ros: error: LMGC90 is not installed in {missing}")
    assert "make lmgc90" in err and lmgc90.VENV_ENV in err


def test_the_flag_is_checks_only_and_off_by_default(capsys):
    with pytest.raises(SystemExit):
        main(["tilt", str(SUITE / "lintel_mu0.60.json"), "--second-opinion", "lmgc90"])
    assert "unrecognized arguments: --second-opinion" in capsys.readouterr().err
    assert main(["check", str(SUITE / "lintel_mu0.60.json"), "--json"]) == 0
    assert "second_opinion" not in json.loads(capsys.readouterr().out)


@pytest.mark.long
def test_lmgc90_second_opinion_disagrees_where_ours_is_wrong(capsys):
    """The bar between free pillars at mu 0.6: with no pre-load nothing presses the bar, so it
    falls (closed form); LMGC90 moves the bar alone. Ours (before issue 29's fix: STABLE) is
    compared, not assumed; the lintel, which stands, agrees."""
    assert main(["check", str(SUITE / "pillars_mu0.60.json"), "--json", "--second-opinion",
                 "lmgc90"]) == 0
    report = json.loads(capsys.readouterr().out)
    opinion = report["second_opinion"]
    assert opinion["engine"] == "lmgc90" and opinion["stable"] is False
    assert opinion["moved"] == ["bar"] and opinion["max_disp"] > lmgc90.DISP_TOL
    assert opinion["agrees"] == (report["stable"] is False)
    assert 0 < opinion["time_s"] < 60
    assert main(["check", str(SUITE / "lintel_mu0.60.json"), "--second-opinion", "lmgc90"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("second opinion (LMGC90, 1 s from rest): stands (")
    assert line.endswith("agrees with rbe_ros (STABLE)")


@pytest.mark.long
def test_a_verdict_that_flips_with_lmgc90s_relaxation_is_recorded_as_undecided():
    """benchmarks/lmgc90_sensitivity.py's evidence, rerun: the 30 deg block under a fixed bar
    at mu 0.55 (0.95 tan 30 deg) stands as make bench-lmgc90 runs LMGC90 (NLGS relaxation
    0.1) and slides with plain Gauss-Seidel (relaxation 1, in a patched copy of the
    extension): two solutions of the same contact problem, so the committed verdict file
    says LMGC90 does not decide it. The time step halved keeps the verdict."""
    from rbe_ros.io.scene_json import load_scene
    from rbe_ros.scene import gravity_down
    name = "v_incline_pressed30_mu0.55"
    folder = SUITE / "variants"
    record = json.loads((folder / "lmgc90_verdicts.json").read_text())["scenes"][name]
    scene = gravity_down(load_scene(folder / f"{name}.json"))
    python = lmgc90.installed_python()
    runs = {setting: lmgc90.check(scene, record["mu"], python, numerics=numerics)
            for setting, numerics in (("base", {}), ("dt/2", {"dt": lmgc90.DT / 2}),
                                      ("relax1", {"nlgs": {"relax": 1.0}}))}
    assert {s: r["stable"] for s, r in runs.items()} == {
        "base": True, "dt/2": True, "relax1": False}
    assert runs["relax1"]["moved"] == ["block"]
    assert record["decides"] is False and record["sensitivity"]["relax1"] == "falls"
