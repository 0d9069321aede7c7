"""Campaign files and the Dask engine (shipid.campaign): validation, serial == 2-worker LocalCluster, failures."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from shipid.campaign import Engine, load_campaign, member_seeds, run_campaign
from shipid.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"
EST = ["b1", "b2", "b3", "b4", "c1", "c2", "c3"]


def _campaign(tmp_path, fits, **top) -> Path:
    p = tmp_path / "camp.json"
    p.write_text(json.dumps({"fits": fits, **top}))
    return p


def _short_logs(tmp_path) -> dict:
    """The first 40 s of two bundled logs (keeps the fits of the engine tests quick)."""
    out = {}
    for name in ("kcs_tc_p35", "kcs_zz_m10"):
        lines = (DATA / f"{name}.csv").read_text().splitlines()
        p = tmp_path / f"{name}_40s.csv"
        p.write_text("\n".join(lines[:401]) + "\n")
        out[name] = str(p)
    return out


def _fits(tmp_path):
    logs = _short_logs(tmp_path)
    return [
        {"name": "tc", "logs": [logs["kcs_tc_p35"]], "estimate": EST, "params": "synthetic-truth",
         "draws": 20, "manoeuvres": ["turning:35"]},
        {"name": "zz", "logs": [logs["kcs_zz_m10"]], "estimate": EST, "params": "synthetic-truth", "passes": 1},
        {"name": "bad", "logs": [logs["kcs_zz_m10"]], "params": "no-such-set"},
    ]


@pytest.mark.parametrize("fits, top, match", [
    ([{"name": "a", "logs": ["x.csv"]}], {}, r"logs\[0\] 'x.csv' not found"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")], "pases": 2}], {}, r"fits\[0\] \('a'\): unknown key 'pases'"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")], "passes": "2"}], {}, r"'passes' must be integer, got '2'"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")], "refine": 1}], {}, r"'refine' must be true/false"),
    ([{"logs": [str(DATA / "kcs_zz_m10.csv")]}], {}, r"'name' is required"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")], "manoeuvres": ["circle:3"]}], {}, r"manoeuvre 'circle:3'"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")]}] * 2, {}, r"must be unique"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")]}], {"seeds": 1}, r"unknown top-level key 'seeds'"),
    ([], {"sweeps": [{"name": "s", "model": "kcs-response", "rudder": [10, "x"]}]},
     r"sweeps\[0\] \('s'\): 'rudder' must be a non-empty list of finite numbers"),
    ([], {"sweeps": [{"name": "s", "model": "kcs-response", "rudder": [-10]}]}, r"'rudder' values must be positive"),
    ([], {"sweeps": [{"name": "s", "kind": "glider", "rudder": [10]}]}, r"unknown key 'rudder' for a glider sweep"),
    ([], {"sweeps": [{"name": "s", "kind": "circle"}]}, r"'kind' must be one of turning, glider"),
    ([], {"sweeps": [{"name": "s", "rudder": [10]}]}, r"'model' is required"),
    ([], {"sweeps": [{"name": "s", "model": "nofile.json"}]}, r"model 'nofile.json' not found"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")]}], {"sweeps": [{"name": "a", "model": "kcs-response"}]},
     r"sweeps\[0\] \('a'\): name 'a' must be unique"),
    ([], {}, r"no members"),
])
def test_campaign_file_errors_are_one_line(tmp_path, fits, top, match):
    p = _campaign(tmp_path, fits, **top)
    with pytest.raises(ValueError, match=match) as e:
        load_campaign(p)
    assert "\n" not in str(e.value) and str(p) in str(e.value)


def test_yaml_campaign_paths_relative_to_the_file(tmp_path):
    pytest.importorskip("yaml")
    (tmp_path / "sub").mkdir()
    p = tmp_path / "sub" / "c.yaml"
    rel = Path("..") / ".." / Path(DATA).relative_to(Path(DATA).parents[1]) / "kcs_tc_p35.csv"
    import shutil

    shutil.copy(DATA / "kcs_tc_p35.csv", tmp_path / "kcs_tc_p35.csv")
    p.write_text("seed: 3\nfits:\n  - name: one\n    logs: [../kcs_tc_p35.csv]\n    passes: 1\n")
    c = load_campaign(p)
    assert c["seed"] == 3 and c["fits"][0]["logs"] == [str((tmp_path / "kcs_tc_p35.csv").resolve())]
    del rel


def test_member_seeds_are_reproducible():
    assert member_seeds(5, 3) == member_seeds(5, 3) and len(set(member_seeds(5, 3))) == 3


#: Two small sweeps: a turning-diameter grid (``shipid sweep``) and a glider launch factorial.
SWEEPS = [{"name": "td", "model": "kcs-response:synthetic-truth", "rudder": [35], "speeds": [1.5, 1.7]},
          {"name": "launch", "kind": "glider", "speed": [1.0, 2.0], "angle_deg": [30, 45], "fin_deg": [0], "cg_m": [0]}]


def test_sweeps_are_campaign_members_with_the_direct_results(tmp_path, capsys):
    """A campaign's sweep members write the tables the direct batched calls give (to the last digit)."""
    from shipid.glider import sweep
    from shipid.manoeuvres import turning_sweep
    from shipid.models import get_model

    p = _campaign(tmp_path, [], sweeps=SWEEPS, seed=2)
    out = tmp_path / "out"
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--no-progress"]) == 0
    assert "td: ok" in capsys.readouterr().out
    summary = json.loads((out / "campaign.json").read_text())
    assert [m["type"] for m in summary["members"]] == ["sweep", "sweep"] and summary["n_failed"] == 0
    td = turning_sweep(get_model("kcs-response", "synthetic-truth"), [35], [1.5, 1.7])
    assert (out / "td" / "sweep.csv").read_text() == td.to_csv(index=False)
    gl = sweep([1.0, 2.0], [30, 45], [0], [0], keep_trajectories=False).launches.reset_index(drop=True)
    assert (out / "launch" / "sweep.csv").read_text() == gl.to_csv(index=False)


@pytest.mark.slow
def test_serial_and_two_dask_workers_give_identical_results(tmp_path):
    pytest.importorskip("distributed")
    p = _campaign(tmp_path, _fits(tmp_path), seed=7, sweeps=SWEEPS)
    serial = run_campaign(p, tmp_path / "serial", engine=Engine(1, progress=False))
    with Engine(2, progress=False) as eng:
        dist = run_campaign(p, tmp_path / "dask", engine=eng)
        import dask

        # the quiet configuration reached the worker processes; each was warmed once, before the members
        assert set(eng._client.run(dask.config.get, "distributed.worker.profile.enabled").values()) == {False}
        assert len(eng.stats["warm"]) == 2 and len(eng.stats["worker_cpu"]) == 2
        assert len(eng.stats["member_seconds"]) == 5 and all(c > 0 for c in eng.stats["member_cpu"])
    assert "LocalCluster, 2 processes" in dist["engine"]
    assert all(m["seconds"] > 0 for m in dist["members"])
    for s in (serial, dist):
        st = {m["name"]: m for m in s["members"]}
        assert st["tc"]["ok"] and st["zz"]["ok"] and not st["bad"]["ok"]
        assert "no-such-set" in st["bad"]["error"] and s["n_failed"] == 1
    for name in ("tc", "zz"):
        a = json.loads((tmp_path / "serial" / name / "result.json").read_text())
        b = json.loads((tmp_path / "dask" / name / "result.json").read_text())
        assert a["coef"] == b["coef"] and a["cov"] == b["cov"]
    a = json.loads((tmp_path / "serial" / "tc" / "predictions.json").read_text())
    b = json.loads((tmp_path / "dask" / "tc" / "predictions.json").read_text())
    assert a == b and a["manoeuvres"]["turning_35_starboard"]["draws"]["n"] == 20
    for name in ("td", "launch"):  # sweep members: byte-identical tables
        assert (tmp_path / "serial" / name / "sweep.csv").read_bytes() == (tmp_path / "dask" / name / "sweep.csv").read_bytes()
    assert [m["type"] for m in dist["members"]] == ["fit"] * 3 + ["sweep"] * 2


def test_member_cost_and_warm_up_settings(tmp_path):
    """Scheduling helpers: the cost estimate grows with logs, passes, refinement and draws (zigzag draws
    dominate); the warm-up runs one member per distinct setting, never the seed or the name."""
    from shipid.campaign import member_cost, warm_specs

    logs = _short_logs(tmp_path)
    a = {"name": "a", "logs": [logs["kcs_tc_p35"]], "passes": 2, "seed": 1}
    b = {**a, "name": "b", "logs": [logs["kcs_tc_p35"], logs["kcs_zz_m10"]], "seed": 2}
    costs = [member_cost(x) for x in (a, b, {**b, "refine": True}, {**b, "draws": 50, "manoeuvres": ["turning:35"]},
                                      {**b, "draws": 50, "manoeuvres": ["zigzag:10/10"]})]
    assert costs[0] < costs[1] < costs[2] < costs[4] and costs[1] < costs[3] < costs[4]
    assert member_cost({"_member": "sweep", "kind": "turning", "rudder": [10, 20], "speeds": [1, 2]}) == \
        2 * member_cost({"_member": "sweep", "kind": "turning", "rudder": [10], "speeds": [1, 2]})
    w = warm_specs([a, b, {**b, "name": "c", "seed": 3}, {**a, "refine": True}, {"_member": "sweep", "name": "s"}])
    assert [x.get("refine") for x in w] == [None, True] and all("seed" not in x and "name" not in x for x in w)
    assert w[0]["logs"] == a["logs"]


def test_campaign_cli_serial(tmp_path, capsys):
    p = _campaign(tmp_path, _fits(tmp_path)[1:], seed=1)
    out = tmp_path / "out"
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--no-progress"]) == 1  # one member failed
    text = capsys.readouterr().out
    assert "bad: FAILED" in text and "zz: ok" in text and "1/2 members completed" in text
    summary = json.loads((out / "campaign.json").read_text())
    assert summary["n_failed"] == 1 and (out / "zz" / "result.json").is_file()
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1"]) == 2  # not empty, no --force
    assert "not empty" in capsys.readouterr().err
