"""Bad command lines for every ``hrlsac`` subcommand: exit 2 with one error line naming the argument, no traceback.

Each subcommand gets unknown options, values of the wrong type, negative or zero counts, out-of-range values
and missing files; all run in this process (``hrlsac_cli.main``), so none of them starts a flight or a
training run (a case that did would be a bug: its argument should have been refused first). An exception a
command does not handle itself ends as one ``error:`` line with exit code 1 and a hint at HRLSAC_TRACEBACK.
"""
from __future__ import annotations

import subprocess
import sys
import types

import pytest
from cli_harness import HRLSAC, assert_clean_error, run_cli
from conftest import free_udp_ports

import hrlsac_cli
from missions.mission_file import LIBRARY_DIR

MISSION = str(LIBRARY_DIR / "demo.yaml")
POLICY = "policies/pretrained/hrl-sac.pt"
MISSING = "/nonexistent/hrlsac-test/file"

# subcommand -> [(arguments, text the error line must contain)]. The text names the bad argument (or, for a
# missing file, the file).
BAD_ARGUMENTS: dict[str, list[tuple[list[str], str]]] = {
    "sitl": [(["--bogus"], "unrecognized arguments: --bogus"),
             (["--seed", "x"], "argument --seed: invalid int value: 'x'"),
             (["--speed", "inf"], "speed must be > 0 and finite"),
             (["--rate", "nan"], "VehicleConfig.physics_rate_hz must be a number in [100, 2000], got nan"),
             (["--api-port", "99999"], "argument --api-port: invalid port '99999' (an integer in 0-65535)"),
             (["--gcs-remote", "-1"], "argument --gcs-remote: invalid port '-1'"),
             (["--api-remote", "x"], "argument --api-remote: invalid port 'x'"),
             (["--wind", "a,b"], "--wind: expected 2 comma-separated numbers, got 'a,b'"),
             (["--gusts", "-3"], "Wind.gust_mps must be a finite number >= 0, got -3.0"),
             (["--home", "nan,0,0"], "GeoPoint.lat_deg must be a number in [-90, 90], got nan"),
             (["--failsafe", "explode"], "argument --failsafe: invalid choice: 'explode'"),
             (["--param", "X"], "--param: expected NAME=VALUE, got 'X'")],
    "demo": [(["--bogus"], "unrecognized arguments: --bogus"),
             (["--seed", "1.5"], "argument --seed: invalid int value: '1.5'")],
    "train": [(["--out", "{tmp}/r", "--steps", "-5"], "TrainConfig.total_steps must be an integer in [1"),
              (["--out", "{tmp}/r", "--steps", "x"], "argument --steps: invalid int value: 'x'"),
              (["--out", "{tmp}/r", "--num-envs", "0"], "TrainConfig.num_envs must be an integer in [1, 4096], got 0"),
              (["--out", "{tmp}/r", "--seed", "-1"], "TrainConfig.seed must be an integer in [0, 4294967295], got -1"),
              (["--out", "{tmp}/r", "--algo", "ppo"], "argument --algo: invalid choice: 'ppo'"),
              (["--out", "{tmp}/r", "--set", "nope=1"], "--set 'nope=1'"),
              (["--out", "{tmp}/r", "--set", "warmup_steps=-1"], "TrainConfig.warmup_steps must be an integer"),
              (["--out", "{tmp}/r", "--resume"], "--resume: no checkpoint in"),
              (["--out", "{tmp}/r", "--set", 'missions=["{tmp}/sweep.yaml"]'],  # a training mission file, broken
               "{tmp}/sweep.yaml: runs: unknown key (allowed: name, flight, geofence, scenario, fleet)"),
              (["--out", "/dev/null/run"], "/dev/null/run"),
              ([], "--out is required: the run folder to write (or --sweep FILE --run NAME)"),
              (["--sweep", MISSING], f"{MISSING}: file not found"),
              (["--sweep", "{tmp}/sweep.yaml"], "{tmp}/sweep.yaml: runs: unknown key"),
              (["--sweep", "{tmp}/sweep.yaml", "--seed", "1", "--set", "gamma=0.9"],
               "--seed, --set: set by the sweep file's run with --sweep; change the sweep file"),
              (["--run", "hrl-sac-default-seed0", "--out", "{tmp}/r"], "--run names a run of a sweep file: give "
                                                                         "--sweep FILE too")],
    "sweep": [([MISSING], MISSING),
              (["{tmp}/sweep.yaml", "--max-parallel", "x"], "argument --max-parallel: invalid int value: 'x'"),
              (["{tmp}/sweep.yaml", "--bogus"], "unrecognized arguments: --bogus")],
    "evaluate": [([MISSING], f"no checkpoint at {MISSING}"),
                 (["{tmp}", "--episodes", "0"], "--episodes must be >= 1, got 0"),
                 (["{tmp}", "--episodes", "-3"], "--episodes must be >= 1, got -3"),
                 (["{tmp}", "--split", "bogus"], "argument --split: invalid choice: 'bogus'"),
                 (["{tmp}", "--workers", "x"], "argument --workers: invalid int value: 'x'")],
    "dataset": [(["info", MISSING], f"{MISSING}: no such dataset directory"),
                (["synth", "{tmp}/ds", "--count", "-1"], "count must be an integer >= 1, got -1"),
                (["synth", "{tmp}/ds", "--count", "0"], "count must be an integer >= 1, got 0"),
                (["synth", "{tmp}/ds", "--count", "x"], "argument --count: invalid int value: 'x'"),
                (["synth", "{tmp}/ds", "--seed", "-1", "--count", "1"], "seed must be an integer >= 0, got -1"),
                (["bogus"], "argument {synth,info}: invalid choice: 'bogus'"),
                ([], "the following arguments are required")],
    "compare": [([MISSING, "--out", "{tmp}/c"], f"{MISSING}: no such run folder"),
                (["{tmp}", "--out", "{tmp}/c"], "no config.json (not a run folder written by hrlsac train)"),
                (["--split", "x"], "argument --split: invalid choice: 'x'"),
                (["--episodes", "x"], "argument --episodes: invalid int value: 'x'")],
    "export": [([MISSING, "-o", "{tmp}/p.pt"], f"no checkpoint at {MISSING}"),
               ([POLICY, "-o", "/nonexistent/p.pt"], "/nonexistent/p.pt: the artifact must be a file in an existing"),
               ([POLICY, "-o", "{tmp}/p.pt", "--format", "onnx"], "argument --format: invalid choice: 'onnx'"),
               (["-o", "{tmp}/p.pt"], "give exactly one of CHECKPOINT and --from-sb3 MODEL.zip"),
               ([POLICY, "-o", "{tmp}/p.pt", "--env-kwargs", "{}"], "--env-kwargs goes with --from-sb3"),
               ([], "the following arguments are required: -o/--out")],
    "policy": [(["info", MISSING], f"{MISSING}: no such file"),
               (["info"], "the following arguments are required: artifact"),
               (["bogus"], "argument COMMAND: invalid choice: 'bogus'"),
               (["info", POLICY, "--bogus"], "unrecognized arguments: --bogus")],
    "mission": [(["replay", MISSION], "one of the arguments --policy --pilot is required"),
                (["replay", MISSING, "--policy", POLICY], f"{MISSING}: file not found"),
                (["replay", MISSION, "--policy", MISSING], f"{MISSING}: no such file"),
                (["replay", MISSION, "--policy", POLICY, "--episodes", "0"],
                 "--episodes must be in [1, 100000], got 0"),
                (["replay", MISSION, "--policy", POLICY, "--episodes", "-2"], "--episodes must be in [1, 100000]"),
                (["replay", MISSION, "--policy", POLICY, "--seed", "-1"], "--seed must be in [0, 4294967295], got -1"),
                (["replay", MISSION, "--policy", POLICY, "--seed", "x"], "argument --seed: invalid int value: 'x'"),
                (["replay", MISSION, "--policy", POLICY, "--out", "/dev/null/out"],
                 "--out /dev/null/out: cannot create the folder"),
                (["replay", MISSION, "--policy", POLICY, "--link-faults", "loss=7"], "loss"),
                (["replay", MISSION, "--policy", POLICY, "--signing-key", MISSING], MISSING),
                (["run", MISSION, "--policy", POLICY], "the following arguments are required: --connect"),
                (["run", MISSION, "--policy", POLICY, "--connect", "bogus"], "cannot use connection 'bogus'"),
                (["run", MISSION, "--policy", POLICY, "--connect", "udpin:127.0.0.1:99999"],
                 "--connect udpin:127.0.0.1:99999: bind(): port must be 0-65535"),
                (["run", MISSION, "--policy", POLICY, "--connect", "udpout:localhost:x"],
                 "cannot use connection 'udpout:localhost:x'"),
                (["run", MISSION, "--policy", POLICY, "--connect", "udpin:x", "--backend", "dronekit"],
                 "argument --backend: invalid choice: 'dronekit'"),
                (["fly"], "argument COMMAND: invalid choice: 'fly'")],
    "keygen": [([], "the following arguments are required: FILE"),
               (["/nonexistent/dir/key"], "/nonexistent/dir/key"),
               (["{tmp}/k", "--bogus"], "unrecognized arguments: --bogus")],
}
CASES = [(command, args, mention) for command, cases in BAD_ARGUMENTS.items() for args, mention in cases]


def test_every_subcommand_is_walked():
    assert set(BAD_ARGUMENTS) == set(hrlsac_cli.COMMANDS)


@pytest.mark.parametrize("command, args, mention", CASES, ids=[f"{c}-{i}" for i, (c, _, _) in enumerate(CASES)])
def test_bad_arguments_are_one_clean_error(tmp_path, command, args, mention):
    (tmp_path / "sweep.yaml").write_text("runs: []\n")
    argv = [arg.replace("{tmp}", str(tmp_path)) for arg in args]
    if command == "sitl":  # a case that was accepted would serve on these ports: keep them free ones
        api, remote, gcs, gcs_remote = map(str, free_udp_ports(4))
        defaults = ["--api-port", api, "--api-remote", remote, "--gcs-port", gcs, "--gcs-remote", gcs_remote]
        argv = defaults + argv
    result = run_cli(command, *argv)
    assert_clean_error(result, f"hrlsac {command}", mention.replace("{tmp}", str(tmp_path)))


@pytest.mark.parametrize("argv, message", [
    (["fly-to-the-moon"], "hrlsac: error: unknown command 'fly-to-the-moon'"),
    (["--bogus"], "hrlsac: error: unknown command '--bogus'"),
    ([], "usage: hrlsac"),
])
def test_the_dispatcher_refuses_what_is_not_a_command(argv, message):
    result = run_cli(*argv)
    assert result.code == 2 and message in result.err + result.out and "Traceback" not in result.err


@pytest.fixture
def failing_command(monkeypatch):
    """A subcommand whose main raises what a bug would: an exception no command turns into its own error."""
    module = types.ModuleType("failing_command")

    def main(argv: list[str], prog: str) -> int:
        raise {"os": OSError(28, "No space left on device"), "bug": KeyError("flight")}.get(argv[0],
                                                                                      RuntimeError("boom\nline 2"))

    module.main = main
    monkeypatch.setitem(sys.modules, "failing_command", module)
    monkeypatch.setitem(hrlsac_cli.COMMANDS, "fail", ("failing_command", "raises"))
    monkeypatch.delenv(hrlsac_cli.TRACEBACK_ENV, raising=False)


def test_an_unexpected_exception_is_one_line_with_a_hint(failing_command):
    result = run_cli("fail", "x")
    assert result.code == 1 and "Traceback" not in result.err
    assert result.err == ("hrlsac fail: error: unexpected RuntimeError: boom (a bug, please report it; rerun with "
                          "HRLSAC_TRACEBACK=1 for the traceback)\n")
    assert "unexpected KeyError: 'flight'" in run_cli("fail", "bug").err
    assert run_cli("fail", "os").err == "hrlsac fail: error: OSError: [Errno 28] No space left on device\n"


def test_the_traceback_is_there_on_request(failing_command, monkeypatch):
    monkeypatch.setenv(hrlsac_cli.TRACEBACK_ENV, "1")
    with pytest.raises(RuntimeError, match="boom"):
        hrlsac_cli.main(["fail", "x"])


def test_bad_arguments_as_a_process():
    api, remote, gcs, gcs_remote = map(str, free_udp_ports(4))
    for argv, message in ((["sitl", "--api-port", "70000"], "argument --api-port: invalid port '70000'"),
                          (["mission", "replay", MISSION, "--policy", POLICY, "--episodes", "0"],
                           "--episodes must be in [1, 100000], got 0"),
                          (["sitl", "--api-port", api, "--api-remote", remote, "--gcs-port", gcs, "--gcs-remote",
                            gcs_remote, "--speed", "inf"], "speed must be > 0 and finite")):
        result = subprocess.run([*HRLSAC, *argv], capture_output=True, text=True, timeout=120)
        assert result.returncode == 2 and "Traceback" not in result.stderr and message in result.stderr


def test_a_reader_that_goes_away_ends_the_command_quietly(tmp_path):
    """``hrlsac ... | head -1``: the closed pipe ends the command with 141 (SIGPIPE's code), no error line."""
    sweep = tmp_path / "many.yaml"
    sweep.write_text(f"steps: 1000\nseeds: {list(range(5000))}\n")  # a dry run prints one line per run
    process = subprocess.Popen([*HRLSAC, "sweep", str(sweep), "--dry-run"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    assert process.stdout.readline().startswith(b"sweep many: 5000 runs")
    process.stdout.close()  # like head after its first line
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) == 141 and err == ""
