"""Digests of what the stack writes for fixed seeds: replays, short training runs, an evaluation, an export.

Run it before and after a change that must not change behaviour (a refactoring, a file move) and compare:

    python benchmarks/output_digests.py --out /tmp/before.json
    ... change ...
    python benchmarks/output_digests.py --compare /tmp/before.json

Everything runs through the ``hrlsac`` command (its interface is what users rely on), in a temporary folder.
What is digested, and what is left out because it is not determined by the seed:
- mission replays: ``flight.tlog`` and ``report.json`` byte for byte (both are on the simulated clock; the
  temporary folder's name, which reports quote, is replaced by a constant in every file); each tlog also as its
  MAVLink frames alone (``flight.tlog frames``) and as its timestamps counted from the first
  (``flight.tlog times``), so that a change of the tlog's start time shows as that alone;
- training runs: ``config.json`` byte for byte, ``progress.csv`` without its ``steps_per_s`` column (wall clock),
  and every tensor, array and number of ``checkpoint.pt`` except the pickled environment (its bytes name the
  environment's module, which a file move changes; the evaluation and replays below depend on it anyway);
- ``hrlsac evaluate``: the metrics file byte for byte;
- ``hrlsac export``: the artifact's behaviour, as the tlog and report of a replay flown with it, without the
  report's ``policy_sha256`` (the artifact's bytes carry its time of writing and name the Python modules it was
  scripted from).
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
import torch

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HRLSAC = [sys.executable, "-c", "import sys, hrlsac_cli; sys.exit(hrlsac_cli.main())"]


def _run(*args: str) -> None:
    subprocess.run([*HRLSAC, *args], cwd=REPO, check=True, stdout=subprocess.DEVNULL)


def _file_digest(path: str, work: str) -> str:
    """The file's bytes, with the temporary folder's name (reports quote the paths they read) made constant."""
    with open(path, "rb") as handle:
        return hashlib.sha256(handle.read().replace(work.encode(), b"WORK")).hexdigest()


def _without_key(value, key: str):
    if isinstance(value, dict):
        return {k: _without_key(v, key) for k, v in value.items() if k != key}
    if isinstance(value, list):
        return [_without_key(v, key) for v in value]
    return value


def _report_digest_without_artifact_hash(path: str, work: str) -> str:
    """A replay report without ``policy_sha256``: an export's bytes carry its time of writing."""
    with open(path) as handle:
        report = _without_key(json.loads(handle.read().replace(work, "WORK")), "policy_sha256")
    return hashlib.sha256(json.dumps(report, sort_keys=True).encode()).hexdigest()


def _progress_digest(path: str) -> str:
    """progress.csv without the wall-clock column."""
    with open(path, newline="") as handle:
        rows = [{k: v for k, v in row.items() if k != "steps_per_s"} for row in csv.DictReader(handle)]
    return hashlib.sha256(json.dumps(rows).encode()).hexdigest()


def _feed(digest, value) -> None:
    """Hash a checkpoint value: tensors and arrays by dtype, shape and bytes; containers in order."""
    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().contiguous()
        digest.update(f"T{value.dtype}{tuple(value.shape)}".encode())
        digest.update(value.reshape(-1).view(torch.uint8).numpy().tobytes())
    elif isinstance(value, np.ndarray):
        digest.update(f"A{value.dtype}{value.shape}".encode() + np.ascontiguousarray(value).tobytes())
    elif isinstance(value, dict):
        for key in value:
            digest.update(f"K{key!r}".encode())
            _feed(digest, value[key])
    elif isinstance(value, (list, tuple)):
        digest.update(f"L{len(value)}".encode())
        for item in value:
            _feed(digest, item)
    else:
        digest.update(repr(value).encode())


def _checkpoint_digest(path: str) -> str:
    state = torch.load(path, weights_only=False)
    state.pop("env")
    digest = hashlib.sha256()
    _feed(digest, state)
    return digest.hexdigest()


def _tlog_records(path: str) -> list[tuple[int, bytes]]:
    """A tlog's (timestamp in microseconds, MAVLink frame) records."""
    with open(path, "rb") as handle:
        data = handle.read()
    records, at = [], 0
    while at < len(data):
        stamp, frame = int.from_bytes(data[at:at + 8], "big"), data[at + 8:]
        if frame[0] == 0xFD:  # MAVLink 2: 10-byte header, payload, CRC, and the signature if flagged
            length = 12 + frame[1] + (13 if frame[2] & 1 else 0)
        elif frame[0] == 0xFE:  # MAVLink 1: 6-byte header, payload, CRC
            length = 8 + frame[1]
        else:
            raise ValueError(f"{path}: no MAVLink frame at byte {at + 8}")
        records.append((stamp, frame[:length]))
        at += 8 + length
    return records


def _tlog_digests(path: str) -> dict[str, str]:
    """The tlog's frames without their timestamps, and its timestamps counted from the first."""
    records = _tlog_records(path)
    frames = hashlib.sha256(b"".join(frame for _, frame in records)).hexdigest()
    first = records[0][0] if records else 0
    times = hashlib.sha256(" ".join(str(stamp - first) for stamp, _ in records).encode()).hexdigest()
    return {"frames": frames, "times": times}


def _replay(digests: dict, name: str, work: str, *args: str) -> None:
    out = os.path.join(work, name)
    _run("mission", "replay", "--no-video", "--quiet", "--out", out, *args)
    for folder, _, files in sorted(os.walk(out)):
        for file in sorted(files):
            path = os.path.join(folder, file)
            key = f"{name}/{os.path.relpath(path, out)}"
            digests[key] = _file_digest(path, work)
            if file.endswith(".tlog"):
                digests.update({f"{key} {part}": digest for part, digest in _tlog_digests(path).items()})


def _train(digests: dict, name: str, work: str, *args: str) -> str:
    out = os.path.join(work, name)
    _run("train", "--quiet", "--out", out, *args)
    digests[f"{name}/config.json"] = _file_digest(os.path.join(out, "config.json"), work)
    digests[f"{name}/progress.csv"] = _progress_digest(os.path.join(out, "progress.csv"))
    digests[f"{name}/checkpoint.pt"] = _checkpoint_digest(os.path.join(out, "checkpoint.pt"))
    return out


def collect(work: str) -> dict[str, str]:
    digests: dict[str, str] = {}
    demo = "missions/library/demo.yaml"
    _replay(digests, "replay-hrl", work, demo, "--policy", "policies/pretrained/hrl-sac.pt")
    _replay(digests, "replay-sac", work, demo, "--policy", "policies/pretrained/sac.pt", "--episodes", "2",
            "--seed", "4")
    _replay(digests, "replay-faults", work, demo, "--policy", "policies/pretrained/hrl-sac.pt", "--seed", "2",
            "--link-faults", "loss=0.1,latency_ms=50,jitter_ms=20,outage=30:2")
    short = ["--steps", "1500", "--num-envs", "2", "--set", "warmup_steps=500"]
    hrl = _train(digests, "train-hrl", work, "--algo", "hrl-sac", "--seed", "3", *short)
    _train(digests, "train-sac", work, "--algo", "sac", "--seed", "5", *short)
    metrics = os.path.join(work, "eval.json")
    _run("evaluate", hrl, "--split", "val", "--episodes", "8", "--out", metrics)
    digests["evaluate/eval.json"] = _file_digest(metrics, work)
    artifact = os.path.join(work, "policy.pt")
    _run("export", hrl, "-o", artifact)
    _replay(digests, "replay-exported", work, demo, "--policy", artifact, "--accept-flight-mismatch")
    digests["replay-exported/report.json"] = _report_digest_without_artifact_hash(
        os.path.join(work, "replay-exported", "report.json"), work)
    return digests


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="write the digests to this JSON file")
    parser.add_argument("--compare", help="a digest file written earlier: report every output that differs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as work:
        digests = collect(work)
    text = json.dumps(digests, indent=2, sort_keys=True)
    if args.out:
        with open(args.out + ".tmp", "w") as handle:
            handle.write(text + "\n")
        os.replace(args.out + ".tmp", args.out)
    print(text)
    if args.compare:
        with open(args.compare) as handle:
            before = json.load(handle)
        differ = sorted(k for k in before.keys() | digests.keys() if before.get(k) != digests.get(k))
        for key in differ:
            print(f"DIFFERS: {key}", file=sys.stderr)
        print(f"{len(digests) - len(differ)} of {len(before.keys() | digests.keys())} outputs identical")
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
