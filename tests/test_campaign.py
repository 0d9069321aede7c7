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
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")]}] * 2, {}, r"name .a. is used twice"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")]}], {"seeds": 1}, r"unknown top-level key 'seeds'"),
    ([], {"sweeps": [{"name": "s", "model": "kcs-response", "rudder": [10, "x"]}]},
     r"sweeps\[0\] \('s'\): 'rudder' must be a non-empty list of finite numbers"),
    ([], {"sweeps": [{"name": "s", "model": "kcs-response", "rudder": [-10]}]}, r"'rudder' values must be positive"),
    ([], {"sweeps": [{"name": "s", "kind": "glider", "rudder": [10]}]}, r"unknown key 'rudder' for a glider sweep"),
    ([], {"sweeps": [{"name": "s", "kind": "circle"}]}, r"'kind' must be one of turning, glider"),
    ([], {"sweeps": [{"name": "s", "rudder": [10]}]}, r"'model' is required"),
    ([], {"sweeps": [{"name": "s", "model": "nofile.json"}]}, r"model 'nofile.json' not found"),
    ([{"name": "a", "logs": [str(DATA / "kcs_zz_m10.csv")]}], {"sweeps": [{"name": "a", "model": "kcs-response"}]},
     r"sweeps\[0\] \('a'\): name 'a' is used twice"),
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
    assert "bad: FAILED" in text and "zz: ok" in text and "2 members: 1 ok, 0 flagged, 1 failed" in text
    summary = json.loads((out / "campaign.json").read_text())
    assert summary["n_failed"] == 1 and (out / "zz" / "result.json").is_file()
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1"]) == 2  # not empty, no --force
    assert "not empty" in capsys.readouterr().err


# --------------------------------------------------------------------------- a campaign stays in its folder
@pytest.mark.parametrize("name, match", [
    ("..", "must be a plain file name"), (".", "must be a plain file name"), ("a\n", "must be a plain file name"),
    (".hidden", "must be a plain file name"), ("a/b", "must be a plain file name"), ("-rf", "must be a plain file name"),
    ("campaign.json", "is reserved"), ("Campaign.Journal", "is reserved"), ("nul", "is reserved"), ("x" * 101, "plain"),
])
def test_member_names_are_plain_file_names(tmp_path, name, match):
    p = _campaign(tmp_path, [{"name": name, "logs": [str(DATA / "kcs_zz_m10.csv")]}])
    with pytest.raises(ValueError, match=match) as e:
        load_campaign(p)
    assert "\n" not in str(e.value) and str(p) in str(e.value)


def test_names_that_differ_only_in_case_are_one_name(tmp_path):
    log = str(DATA / "kcs_zz_m10.csv")
    p = _campaign(tmp_path, [{"name": "Run", "logs": [log]}, {"name": "run", "logs": [log]}])
    with pytest.raises(ValueError, match="name 'run' is used twice"):
        load_campaign(p)


def test_a_member_folder_that_links_out_is_refused_before_anything_runs(tmp_path, capsys):
    logs = _short_logs(tmp_path)
    p = _campaign(tmp_path, [{"name": "zz", "logs": [logs["kcs_zz_m10"]], "passes": 1}])
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / "zz").symlink_to(elsewhere)
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--force"]) == 2
    err = capsys.readouterr().err
    assert "zz: exists and is not a folder of this campaign (a link or a file)" in err
    assert list(elsewhere.iterdir()) == [] and not (out / "campaign.json").exists()


def test_force_removes_a_failed_members_old_result(tmp_path, capsys):
    """--force runs every member again: a member that now fails keeps no stale result beside the summary."""
    logs = _short_logs(tmp_path)
    bad = tmp_path / "bad.csv"
    bad.write_text("time,x\n0,1\n")
    p = _campaign(tmp_path, [{"name": "zz", "logs": [logs["kcs_zz_m10"]], "passes": 1},
                             {"name": "m", "logs": [str(bad)]}])
    out = tmp_path / "out"
    (out / "m").mkdir(parents=True)
    (out / "m" / "result.json").write_text('{"old": true}')
    (out / "m" / "notes.txt").write_text("mine")  # not a file the campaign writes: kept
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--force"]) == 1
    text = capsys.readouterr().out
    assert "m: FAILED" in text and "2 members: 1 ok, 0 flagged, 1 failed" in text
    assert not (out / "m" / "result.json").exists() and (out / "m" / "notes.txt").read_text() == "mine"


def test_members_carry_the_fits_verdict(tmp_path, capsys):
    """A fit that `shipid fit` grades a defect (exit 3: here a log whose rudder is in rad/57.3, which the reader
    cannot see and the rudder's yaw coefficient shows) is flagged, not ok;
    the summary counts ok / flagged / failed and the exit status is 3."""
    import pandas as pd

    lines = (DATA / "kcs_zz_m10.csv").read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    df = pd.read_csv(DATA / "kcs_zz_m10.csv", comment="#")
    df["delta [rad]"] = df["delta [rad]"] / 57.3
    flip = tmp_path / "vflip.csv"
    flip.write_text("\n".join(head) + "\n" + df.to_csv(index=False))
    p = _campaign(tmp_path, [{"name": "good", "logs": [str(DATA / "kcs_zz_m10.csv")], "passes": 1},
                             {"name": "vflip", "logs": [str(flip)]}])
    out = tmp_path / "out"
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1"]) == 3
    text = capsys.readouterr().out
    assert "good: ok" in text and "vflip: flagged: " in text and "--units delta=deg" in text
    assert "2 members: 1 ok, 1 flagged, 0 failed" in text
    s = json.loads((out / "campaign.json").read_text())
    st = {m["name"]: m for m in s["members"]}
    assert st["vflip"]["status"] == "flagged" and st["vflip"]["reasons"] and s["n_flagged"] == 1
    from shipid.campaign import fit_exit_status

    r = json.loads((out / "vflip" / "result.json").read_text())
    assert fit_exit_status(r)[0] in (3, 4) and fit_exit_status(json.loads((out / "good" / "result.json").read_text()))[0] == 0
    # the same log through `shipid fit`: the same judgement
    assert main(["fit", str(flip), "-o", str(tmp_path / "f.json")]) in (3, 4)
    capsys.readouterr()


def test_readers_warnings_are_kept_in_the_members_result(tmp_path):
    import pandas as pd

    lines = (DATA / "kcs_zz_m10.csv").read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    df = pd.read_csv(DATA / "kcs_zz_m10.csv", comment="#")
    df["n [rps]"] = 0.0
    dead = tmp_path / "n0.csv"
    dead.write_text("\n".join(head) + "\n" + df.to_csv(index=False))
    p = _campaign(tmp_path, [{"name": "n0", "logs": [str(dead)], "passes": 1}])
    s = run_campaign(p, tmp_path / "out")
    w = s["members"][0]["warnings"]
    assert any("reads 0 in 100 % of the samples" in x for x in w), w
    r = json.loads((tmp_path / "out" / "n0" / "result.json").read_text())
    assert r["extra"]["reader_warnings"] == w


def test_workers_bounded_by_the_machine():
    import os

    from shipid.campaign import Engine

    n = os.cpu_count() or 1
    with pytest.raises(ValueError, match=rf"--workers 100000: give 1 to {n} \(this machine has {n} CPUs"):
        Engine(100000)
    with pytest.raises(ValueError, match=r"--workers 0: give 1 to"):
        Engine(0)


def test_a_scheduler_that_never_answers_is_an_error_in_stated_time(monkeypatch):
    pytest.importorskip("distributed")
    import socket

    import shipid.campaign as C

    monkeypatch.setattr(C, "SCHEDULER_TIMEOUT", 2.0)
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    try:
        with pytest.raises(ValueError, match=r"--scheduler tcp://127\.0\.0\.1:\d+: cannot connect \(no answer within 2 s"):
            C.Engine(scheduler=f"tcp://127.0.0.1:{srv.getsockname()[1]}", progress=False)._start()
    finally:
        srv.close()


# --------------------------------------------------------------------------- nothing finished is lost
def _kill_campaign(tmp_path, p, out, sig, after: int, delay: float, must_kill: bool = False):
    """Run the campaign CLI in a child; send ``sig`` ``delay`` s after it reported its ``after``-th finished
    member (0: after start-up); returns the members it reported finished. With ``must_kill``, a run that
    ended before the signal fails the test (it would have tested nothing)."""
    import os
    import subprocess
    import sys
    import threading
    import time

    proc = subprocess.Popen([sys.executable, "-m", "shipid", "campaign", str(p), "-o", str(out), "--workers", "1"],
                            cwd=Path(__file__).resolve().parents[1], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    said: list = []
    err: list = []
    reached = threading.Event()
    if after == 0:
        reached.set()

    def read_out():
        for line in proc.stdout:
            if line.rstrip().endswith(": ok") or ": flagged" in line:
                said.append(line.split(":")[0])
                if len(said) >= after:
                    reached.set()
        reached.set()

    threads = [threading.Thread(target=read_out), threading.Thread(target=lambda: err.append(proc.stderr.read()))]
    for th in threads:
        th.start()
    reached.wait(timeout=600)
    time.sleep(delay)
    if proc.poll() is None:
        os.kill(proc.pid, sig)
    proc.wait(timeout=600)
    if must_kill:
        assert proc.returncode == -sig, f"the campaign ended (exit {proc.returncode}) before the signal reached it"
    for th in threads:
        th.join(timeout=60)
    assert "Traceback" not in "".join(err), err
    return list(said)


def _three_members(tmp_path) -> Path:
    """Three short fits; the second also propagates 80 draws through a turning circle, so it runs about a
    second, long enough for a kill sent just after the first member finished to land inside it."""
    logs = _short_logs(tmp_path)
    fits = [{"name": n, "logs": [logs["kcs_zz_m10"]], "passes": 1, "estimate": EST[:4 + i]}
            for i, n in enumerate(["a", "b", "c"])]
    fits[1].update(draws=80, manoeuvres=["turning:35"])
    return _campaign(tmp_path, fits)


def _kill_and_resume(tmp_path, sig, after, delay, ref=None, must_kill=False):
    names = ["a", "b", "c"]
    p = _three_members(tmp_path)
    out = tmp_path / f"out-{sig}-{after}-{delay:.2f}"
    done = _kill_campaign(tmp_path, p, out, sig, after, delay, must_kill)
    kept = {n: (out / n / "result.json").read_bytes() for n in done}  # every member said finished has its file
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--resume", "--no-progress"]) == 0
    for n in names:
        assert (out / n / "result.json").is_file()
    for n, b in kept.items():
        assert (out / n / "result.json").read_bytes() == b
    s = json.loads((out / "campaign.json").read_text())
    assert s["n_ok"] == 3 and s["n_resumed"] >= len(done)
    if ref is not None:  # the same results as a run that was never interrupted
        for n in names:
            assert (out / n / "result.json").read_bytes() == (ref / n / "result.json").read_bytes()
    return done


def test_sigkill_then_resume_loses_no_finished_member(tmp_path, capsys):
    import signal

    done = _kill_and_resume(tmp_path, signal.SIGKILL, 1, 0.05, must_kill=True)  # killed as the second member runs
    capsys.readouterr()
    assert done == ["a"]


@pytest.mark.slow
def test_kills_at_random_points_then_resume(tmp_path, capsys):
    """SIGTERM and SIGKILL at random times (seeded) over the run; after --resume every member is there, those
    finished before the kill unchanged, all equal to an uninterrupted run's."""
    import random
    import signal

    ref = tmp_path / "ref"
    p = _three_members(tmp_path)
    assert main(["campaign", str(p), "-o", str(ref), "--workers", "1", "--no-progress"]) == 0
    rng = random.Random(29)
    seen = set()
    for sig in (signal.SIGTERM, signal.SIGKILL) * 3:  # after 0, 1 or 2 finished members, at a random moment
        seen.add(len(_kill_and_resume(tmp_path, sig, rng.randint(0, 2), rng.uniform(0.0, 1.0), ref)))
    capsys.readouterr()
    assert len(seen) >= 2  # the kills fell at different stages of the run


def test_resume_refuses_a_changed_campaign_and_a_folder_without_journal(tmp_path, capsys):
    logs = _short_logs(tmp_path)
    p = _campaign(tmp_path, [{"name": "a", "logs": [logs["kcs_zz_m10"]], "passes": 1}])
    out = tmp_path / "out"
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--no-progress"]) == 0
    p.write_text(json.dumps({"fits": [{"name": "a", "logs": [logs["kcs_zz_m10"]], "passes": 2}]}))
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--resume"]) == 2
    assert "written for another version of the campaign" in capsys.readouterr().err
    other = tmp_path / "other"
    other.mkdir()
    (other / "x.txt").write_text("mine")
    assert main(["campaign", str(p), "-o", str(other), "--workers", "1", "--resume"]) == 2
    assert "no campaign.journal in this folder, so nothing to resume" in capsys.readouterr().err
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--resume", "--force"]) == 2
    assert "--force and --resume: give one" in capsys.readouterr().err


@pytest.mark.slow
def test_a_member_that_kills_its_worker_is_retried_then_reported_and_the_others_complete():
    """A member whose worker process dies is started again MEMBER_RETRIES times, then reported as that
    member's failure (Dask's KilledWorker, one line); the other members complete."""
    pytest.importorskip("distributed")
    from shipid.campaign import MEMBER_RETRIES

    seen = []
    with Engine(2, progress=False) as eng:
        out = eng.map(eval, ["1 + 1", "__import__('os')._exit(3)", "2 + 2"], on_result=seen.append)
    assert [o.ok for o in out] == [True, False, True] and out[0].value == 2 and out[2].value == 4
    assert out[1].error == (f"its worker process died {MEMBER_RETRIES + 1} times running it (out of memory, or a "
                            "crash); run it alone with --workers 1 to see why")
    assert sorted(o.index for o in seen) == [0, 1, 2]


def test_a_journal_that_is_a_fifo_is_refused_not_read(tmp_path, capsys):
    import os

    logs = _short_logs(tmp_path)
    p = _campaign(tmp_path, [{"name": "a", "logs": [logs["kcs_zz_m10"]], "passes": 1}])
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / "campaign.journal")
    assert main(["campaign", str(p), "-o", str(out), "--workers", "1", "--resume"]) == 2
    assert "campaign.journal: is a FIFO (named pipe)" in capsys.readouterr().err
