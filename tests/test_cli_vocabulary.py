"""One CLI vocabulary: every command and option explains itself, an option word means one thing in every
command, and the old spellings still work for one release, saying what to use instead."""
from __future__ import annotations

import argparse
import re

import pytest

from shipid.cli import build_parser, main

#: Option words used by more than one command, what each means, and a pattern its help text must match
#: (so that a command giving the word another meaning fails here).
VOCABULARY = {
    "--output": ("the file or folder the command writes", r"."),
    "--force": ("replace an existing output", r"overwrite|write into|replace|into a used output"),
    "--seed": ("random seed", r"seed"),
    "--dt": ("a time step in seconds", r"\[s\]"),
    "--every": ("a sample stride: use every K-th sample", r"every K|K-th"),
    "--method": ("the solution method of an optimal-control or routing problem", r"indirect|Zermelo"),
    "--integrator": ("the time integrator of a simulation", r"RK4"),
    "--model": ("a model: MODEL[:SET] or a fit RESULT.json", r"\[:SET\]"),
    "--lpp": ("ship length between perpendiculars [m]", r"length.*\[m\]"),
    "--speed": ("speed [m/s] (a value or a range)", r"\[m/s\]"),
    "--angle": ("launch angle [deg]", r"\[deg\]"),
    "--fin": ("fin incidence [deg]", r"\[deg\]"),
    "--cg": ("CG offset [m]", r"\[m\]"),
    "--side": ("side of the turn / first zigzag execute", r"side"),
    "--zigzag": ("zigzag rudder/check angles [deg]", r"rudder/check|rudder/heading"),
    "--rudder-rate": ("rudder rate [deg/s]", r"\[deg/s\]"),
    "--rtol": ("relative tolerance of the adaptive integrator", r"relative tolerance"),
    "--draws": ("parameter draws propagating a fit's uncertainty", r"draws"),
    "--samples": ("MCMC samples JSON to draw from", r"MCMC samples"),
    "--passes": ("EKF passes", r"EKF passes"),
    "--progress": ("show progress", r"progress"),
    "--no-progress": ("no progress output", r"progress"),
    "--horizon": ("prediction horizons [s]", r"horizons \[s\]"),
    "--start-every": ("spacing of the horizon starts [s]", r"\[s\]"),
    "--no-closed-loop": ("skip the closed-loop standard manoeuvre", r"closed-loop"),
    "--workers": ("worker processes", r"worker"),
    "--scheduler": ("a Dask scheduler address", r"scheduler"),
    "--wind": ("wind forces from the logs' wind", r"wind"),
    "--current": ("a uniform current as extra states", r"current"),
}

#: Commands whose result is printed; for them -o/--output is optional (it also saves what is printed).  Every
#: other command's product is a file, and -o/--output is required.
PRINTING = {"log", "metrics", "simulate", "sweep", "demo", "models"}

#: Old spellings: (argv to parse, the option's destination, the value it must carry, the new word it names).
ALIASES = [
    (["fit", "log.csv", "-o", "r.json", "--dt", "4"], "every", "4", "--every"),
    (["fit", "log.csv", "-o", "r.json", "--params", "synthetic-truth"], "params", "synthetic-truth", "--model"),
    (["crossval", "a.csv", "b.csv", "-o", "cv.json", "--dt", "2"], "every", "2", "--every"),
    (["demo", "--output-dir", "out"], "output", "out", "--output"),
    (["simulate", "kcs-response", "--turning", "35", "--method", "dopri5"], "integrator", "dopri5", "--integrator"),
    (["sweep", "kcs-response", "--method", "dopri5"], "integrator", "dopri5", "--integrator"),
    (["simulate", "kcs-response", "--turning", "35", "--draws-seed", "7"], "seed", 7, "--seed"),
    (["plan", "paper-1", "-o", "p.json", "--solver", "ipopt"], "optimizer", "ipopt", "--optimizer"),
    (["route", "paper-zermelo", "-o", "r.json", "--solver", "pmp"], "method", "pmp", "--method"),
    (["glider", "launch", "--speed", "5", "--angle", "45", "-o", "g.json", "--params", "paper"], "model", "paper",
     "--model"),
    (["glider", "optimise", "-o", "g.json", "--params", "paper"], "model", "paper", "--model"),
]


def _commands(parser=None, prefix=""):
    """``(name, parser)`` of every command and sub-command."""
    parser = parser or build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                full = f"{prefix}{name}"
                yield full, sub
                yield from _commands(sub, full + " ")


def _options(parser):
    """The visible options of one parser (not help, not hidden aliases, not sub-command lists)."""
    return [a for a in parser._actions if a.option_strings and a.help != argparse.SUPPRESS
            and not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))]


COMMANDS = dict(_commands())


def test_every_command_and_option_explains_itself():
    missing = []
    for name, p in COMMANDS.items():
        if not (p.description or "").strip():
            missing.append(f"shipid {name}: no description")
        for a in p._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) or a.help == argparse.SUPPRESS:
                continue
            if not (a.help or "").strip():
                missing.append(f"shipid {name} {'/'.join(a.option_strings) or a.dest}: no help text")
    assert not missing, "\n".join(missing)


def test_no_option_word_has_two_meanings():
    """A word whose help differs between commands (not one shared definition) must be in VOCABULARY, and its
    help must say the meaning listed there."""
    helps: dict[str, set] = {}
    for name, p in COMMANDS.items():
        for a in _options(p):
            for word in a.option_strings:
                if not word.startswith("--"):
                    continue
                helps.setdefault(word, set()).add(a.help)
                if word in VOCABULARY:
                    meaning, pattern = VOCABULARY[word]
                    assert re.search(pattern, a.help or "", re.I), \
                        f"shipid {name} {word}: help {a.help!r} does not say {meaning!r}"
    varied = sorted(w for w, h in helps.items() if len(h) > 1 and w not in VOCABULARY)
    assert not varied, f"option words explained differently by different commands; give each one meaning in VOCABULARY: {varied}"


def test_output_is_one_option_with_one_rule():
    for name, p in COMMANDS.items():
        for a in _options(p):
            if "-o" in a.option_strings or "--output" in a.option_strings:
                assert a.option_strings == ["-o", "--output"], f"shipid {name}: {a.option_strings}"
                assert a.required == (name.split()[0] not in PRINTING), \
                    f"shipid {name}: -o/--output {'required' if a.required else 'optional'}, against the rule"


def test_a_model_is_named_one_way():
    for name, p in COMMANDS.items():
        for a in p._actions:
            if a.dest in ("model", "params") and a.help != argparse.SUPPRESS:
                assert "[:SET]" in (a.help or "") or "RESULT" in (a.metavar or ""), f"shipid {name} {a.dest}"
    for name in ("simulate", "sweep", "validate"):
        pos = [a for a in COMMANDS[name]._actions if not a.option_strings and a.dest in ("model", "result")]
        assert pos and pos[0].metavar == "MODEL", name


@pytest.mark.parametrize("argv,dest,value,new", ALIASES, ids=[" ".join(a[0][:2]) + " " + a[3] for a in ALIASES])
def test_old_spelling_works_and_names_its_replacement(argv, dest, value, new, capsys):
    args = build_parser().parse_args(argv)
    assert getattr(args, dest) == value
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"is now '{new}'" in err[0] and len(err[0]) <= 300, err
    old = [x for x in argv if x.startswith("--")][-1]
    command = " ".join(x for x in argv[:2] if x in COMMANDS or " ".join(argv[:2]) in COMMANDS)
    parser = COMMANDS[" ".join(argv[:2])] if " ".join(argv[:2]) in COMMANDS else COMMANDS[argv[0]]
    assert all(old not in a.option_strings for a in _options(parser)), f"{command}: {old} is listed in --help"


def test_old_problem_name_works_and_names_its_replacement(tmp_path, capsys, monkeypatch):
    import shipid.commands.route as routing

    seen = []
    monkeypatch.setattr(routing, "_zermelo", lambda args, spec, base, out, csv: seen.append((args.problem, spec)) or 0)
    assert main(["route", "zermelo-paper", "-o", str(tmp_path / "route.json")]) == 0
    assert seen == [("paper-zermelo", {"type": "zermelo", "paper": True, "units": "nautical"})]
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["shipid route: note: 'zermelo-paper' is now 'paper-zermelo'; 'zermelo-paper' works until the next "
                   "release"]


def test_help_of_every_command_prints(capsys):
    for name in COMMANDS:
        with pytest.raises(SystemExit) as exc:
            build_parser().parse_args([*name.split(), "--help"])
        assert exc.value.code == 0
    assert "usage:" in capsys.readouterr().out


def test_fit_model_names_the_start_values(tmp_path):
    import json

    from shipid.commands._common import split_model_option

    def split(argv):
        args = build_parser().parse_args(["fit", "log.csv", "-o", "r.json", *argv])
        split_model_option(args)
        return args.model, args.params

    assert split(["--model", "mmg:kvlcc2"]) == ("mmg", "kvlcc2")
    assert split(["--model", "mmg"]) == ("mmg", None)
    assert split(["--model", "auto:mmg:kvlcc2,response-nl"]) == ("auto:mmg:kvlcc2,response-nl", None)
    res = tmp_path / "start.json"
    res.write_text(json.dumps({"model": "response-nl", "coef": {"a1": -0.1}}))
    assert split(["--model", str(res)]) == ("response-nl", str(res))
    with pytest.raises(ValueError, match="already names the start values"):
        split(["--model", "mmg:kvlcc2", "--params", "kvlcc2"])
