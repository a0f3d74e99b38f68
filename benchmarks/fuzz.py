"""Fuzz the two MAVLink receive paths with random and mutated frames, seeded, and count what happens.

The receive paths:
  * vehicle: ``SimulatedVehicle.receive`` (pymavlink parsing, signing checks, every message handler), with the
    physics stepped every few frames so hostile commands are also flown; once without and once with a signing
    key (with a key nothing fuzzed may arm it or change its mode: the fuzzer does not have the key), and the
    ArduCopter personality without (its own mission, fence and rally protocols and modes);
  * runner: ``autonomy.vehicle_time.receive_telemetry`` (the companion computer's pymavlink connection, VehicleLink,
    the Kalman filter) plus every reading the runner's state machine takes from the link.

Frames: a corpus of valid frames of both directions (MAVLink 1 and 2, unsigned and signed with a key the targets
do not know), then per frame one of: random bytes, bit flips, truncation, a lying length byte, a wrong CRC, an
unknown message id, MAVLink 1/2 marker swapped, the signed flag with a garbage signature, two frames spliced,
or a valid frame whose fields hold hostile values (NaN, inf, extremes, odd modes and enums).

Counted per target: frames, crashes (exceptions escaping the receive path), hangs (a frame taking > 1 s, measured;
a frame still running after 10 s is interrupted), messages decoded, frames rejected (bad data or signing),
invariant violations, and the frame rate.

Usage: python benchmarks/fuzz.py [--frames 1000000] [--seed 0] [--out benchmarks/results/fuzz.json]
The frames and mutations are benchmarks/fuzz_frames.py; the tests (tests/test_fuzz_mavlink.py) import both.
"""
from __future__ import annotations

import argparse
import math
import platform
import random
import resource
import signal
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script from anywhere

from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from autonomy.estimator import PoseEstimator  # noqa: E402
from autonomy.vehicle_link import VehicleLink, enum_name  # noqa: E402
from autonomy.vehicle_time import BootTimeMap, receive_telemetry  # noqa: E402
from fuzz_frames import MUTATIONS, corpus, encoder, fuzz_frame  # noqa: E402
from sitl_bridge.link import MemoryMavConnection, memory_link_pair  # noqa: E402
from sitl_bridge.vehicle import SimulatedVehicle  # noqa: E402
from sitl_bridge.vehicle_config import DEFAULT_HOME, VehicleConfig  # noqa: E402

TARGET_KEY = bytes(range(1, 33))  # what the signed targets use
HANG_S = 1.0
INTERRUPT_S = 10.0
STEP_EVERY = 10  # vehicle physics ticks per fuzzed frames: hostile commands get flown, not only parsed


# ---------------------------------------------------------------------------------------------- targets
class VehicleTarget:
    """The vehicle's receive path on one in-memory link; ``signing_key`` turns signing on; ``autopilot`` picks the
    personality (its own mission, fence and rally protocols and modes)."""

    def __init__(self, signing_key: bytes | None = None, seed: int = 0, autopilot: str = "px4"):
        self.vehicle_end, self.client_end = memory_link_pair("fuzz")
        config = VehicleConfig(seed=seed, signing_key=signing_key, autopilot=autopilot)
        self.vehicle = SimulatedVehicle(config, [self.vehicle_end])
        self.endpoint = self.vehicle.endpoints[0]
        self.frames_since_step = 0
        self.initial_mode = self.vehicle.autopilot.mode

    def feed(self, data: bytes) -> None:
        self.vehicle.receive(self.endpoint, data)
        self.frames_since_step += 1
        if self.frames_since_step >= STEP_EVERY:
            self.frames_since_step = 0
            self.vehicle.step()
            self.client_end.receive()  # what the vehicle said is not needed: keep memory flat

    def decoded(self) -> int:
        mav = self.endpoint.mav
        return mav.total_packets_received - mav.total_receive_errors

    def rejected(self) -> int:
        signing = self.vehicle.signing
        return self.endpoint.bad_frames + (sum(signing.rejected.values()) if signing else 0)

    def details(self) -> dict:
        """Exceptions a message handler raised and the vehicle contained (each is a bug, though not a crash) and
        the signing rejections by reason."""
        signing = self.vehicle.signing
        return {"handler_errors": self.vehicle.handler_errors,
                "signing_rejected": dict(signing.rejected) if signing else None,
                "kept_state": {"unhandled_types": len(self.vehicle.unhandled)}}

    def violations(self) -> list[str]:
        """Safety invariants: a finite state always; with a key, no arming, no mode change, the key kept."""
        vehicle, problems = self.vehicle, []
        state = vehicle.state
        numbers = (state.north_m, state.east_m, state.down_m, state.battery_wh, *vehicle.ground_velocity)
        if not all(math.isfinite(value) for value in numbers):
            problems.append(f"non-finite vehicle state {numbers}")
        if vehicle.config.signing_key is not None:
            if vehicle.autopilot.armed:
                problems.append("armed by an unsigned or forged frame")
            if vehicle.autopilot.mode is not self.initial_mode:
                problems.append(f"mode changed to {vehicle.autopilot.mode} by a forged frame")
            if vehicle.signing is None or vehicle.signing.key != vehicle.config.signing_key:
                problems.append("signing key changed by a forged frame")
        return problems


class RunnerTarget:
    """The companion computer's receive path: pymavlink connection, VehicleLink, Kalman filter, state readings."""

    def __init__(self, signing_key: bytes | None = None):
        self.vehicle_end, client_end = memory_link_pair("fuzz")
        self.time_s = 0.0
        self.link = VehicleLink(MemoryMavConnection(client_end, source_system=1, source_component=191),
                                lambda: self.time_s, signing_key=signing_key)
        self.estimator = PoseEstimator(home=DEFAULT_HOME)
        self.boot_time = BootTimeMap()
        self.accepted = 0

    def feed(self, data: bytes) -> None:
        self.time_s += 0.01
        self.vehicle_end.send(data)
        self.accepted += len(receive_telemetry(self.link, self.estimator, self.boot_time))
        self.vehicle_end.receive()  # the companion's heartbeats: not needed
        self.read_like_the_runner()

    def read_like_the_runner(self) -> None:
        """Every reading the runner's states and failsafes take from the link and the filter."""
        link = self.link
        _ = (link.flight_mode, link.armed, link.home_altitude_amsl(), link.battery_percent(), link.status_texts[-2:],
             link.ack_for(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0), self.estimator.converged)
        if link.discovered and "HEARTBEAT" in link.latest:
            link.vehicle_description()
        if link.acks:  # how the runner names a refused command
            enum_name("MAV_RESULT", link.acks[-1].result)
        if self.estimator.time_s is not None:
            self.estimator.predict_to(self.time_s)

    def decoded(self) -> int:
        mav = self.link.conn.mav
        return mav.total_packets_received - mav.total_receive_errors

    def rejected(self) -> int:
        signing = self.link.signing
        return self.link.conn.mav.total_receive_errors + (sum(signing.rejected.values()) if signing else 0)

    def details(self) -> dict:
        """Messages the runner accepted, and the signing rejections by reason."""
        signing = self.link.signing
        return {"accepted": self.accepted, "signing_rejected": dict(signing.rejected) if signing else None,
                "kept_state": self.kept_state()}

    def kept_state(self) -> dict:
        """How much the receive path keeps: must stay bounded whatever arrives."""
        conn = self.link.conn
        return {"latest_types": len(self.link.latest), "status_texts": len(self.link.status_texts),
                "pymavlink_messages": sum(len(state.messages) for state in conn.sysid_state.values()),
                "pymavlink_params": sum(len(state.params) for state in conn.param_state.values())}

    def violations(self) -> list[str]:
        estimate = self.estimator
        if estimate.time_s is not None and not all(math.isfinite(v) for v in estimate.position_ned):
            return [f"non-finite pose estimate {estimate.position_ned}"]
        return []


def make_targets(seed: int) -> dict[str, object]:
    return {"vehicle": VehicleTarget(None, seed), "vehicle_signed": VehicleTarget(TARGET_KEY, seed),
            "vehicle_ardupilot": VehicleTarget(None, seed, autopilot="ardupilot"),
            "runner": RunnerTarget(None), "runner_signed": RunnerTarget(TARGET_KEY)}


# ---------------------------------------------------------------------------------------------- signing attacks
SIGNING_ATTACKS = ("unsigned", "wrong_key", "replay", "downgrade_mavlink1", "stale")


def _arm(value: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, value, 0, 0, 0, 0, 0, 0)


def signing_attacks(trials: int, seed: int) -> dict:
    """Each attack ``trials`` times on a signed vehicle with a GPS fix: an ARM command that is unsigned, signed
    with a random key, a re-sent captured signed ARM (after the owner disarmed), unsigned MAVLink 1, or signed
    with the right key but a new stream's timestamp over a minute old (a recording from before). Counts how many
    were rejected by signing and how many took effect (armed the vehicle)."""
    rng = random.Random(seed)
    target = VehicleTarget(TARGET_KEY, seed)
    vehicle = target.vehicle
    vehicle.run(70.0)  # a GPS fix, and a clock over a minute past the epoch (room for stale timestamps)
    owner = encoder(255, 190, TARGET_KEY)
    owner.signing.timestamp = vehicle.signing_timestamp()
    results = {attack: {"tried": 0, "rejected": 0, "took_effect": 0} for attack in SIGNING_ATTACKS}
    for _ in range(trials):
        for attack in SIGNING_ATTACKS:
            if attack == "unsigned":
                frame = _arm(1).pack(encoder(255, 190))
            elif attack == "wrong_key":
                frame = _arm(1).pack(encoder(255, 190, rng.randbytes(32)))
            elif attack == "downgrade_mavlink1":
                frame = _arm(1).pack(encoder(255, 190), force_mavlink1=True)
            elif attack == "stale":
                old = encoder(rng.randrange(2, 250), rng.randrange(1, 255), TARGET_KEY)
                old.signing.timestamp = rng.randrange(vehicle.signing_timestamp() - 61 * 100_000)
                frame = _arm(1).pack(old)
            else:  # replay: the owner arms and disarms, the attacker re-sends the captured ARM
                frame = _arm(1).pack(owner)
                target.feed(frame)
                results[attack]["owner_arm_accepted"] = results[attack].get("owner_arm_accepted", 0) + \
                    vehicle.autopilot.armed  # the control: the same frame, first time, does arm
                target.feed(_arm(0).pack(owner))
            rejected_before = sum(vehicle.signing.rejected.values())
            target.feed(frame)
            vehicle.step()
            figures = results[attack]
            figures["tried"] += 1
            figures["rejected"] += sum(vehicle.signing.rejected.values()) - rejected_before
            if vehicle.autopilot.armed:
                figures["took_effect"] += 1
                target.feed(_arm(0).pack(owner))
    for figures in results.values():
        figures["share_rejected"] = figures["rejected"] / figures["tried"] if figures["tried"] else None
    return results


# ---------------------------------------------------------------------------------------------- the run
class FrameHang(Exception):
    """Raised by the watchdog in a frame that has run for INTERRUPT_S."""


def _interrupt(signum, frame) -> None:
    raise FrameHang(f"frame still running after {INTERRUPT_S:g} s")


def run(frames: int, seed: int, progress: bool = True) -> dict:
    rng = random.Random(seed)
    corpus_frames = corpus(rng)
    targets = make_targets(seed)
    stats = {name: {"frames": 0, "crashes": 0, "hangs": 0, "max_frame_ms": 0.0, "violations": 0, "seconds": 0.0}
             for name in targets}
    examples: list[dict] = []
    by_mutation: dict[str, int] = {kind: 0 for kind in MUTATIONS}
    signal.signal(signal.SIGALRM, _interrupt)
    started = time.perf_counter()
    for index in range(frames):
        kind, data = fuzz_frame(rng, corpus_frames)
        by_mutation[kind] += 1
        for name, target in targets.items():
            figures = stats[name]
            signal.setitimer(signal.ITIMER_REAL, INTERRUPT_S)
            begin = time.perf_counter()
            try:
                target.feed(data)
            except Exception as exc:  # noqa: BLE001 - counting what escapes is the point
                figures["crashes"] += 1
                if isinstance(exc, FrameHang):
                    figures["hangs"] += 1
                if len(examples) < 20:
                    examples.append({"target": name, "mutation": kind, "error": repr(exc), "frame": data.hex()})
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            elapsed = time.perf_counter() - begin
            figures["seconds"] += elapsed
            figures["frames"] += 1
            figures["max_frame_ms"] = max(figures["max_frame_ms"], elapsed * 1000.0)
            if elapsed > HANG_S:
                figures["hangs"] += 1
        if index % 1000 == 999:
            for name, target in targets.items():
                problems = target.violations()
                if problems:
                    stats[name]["violations"] += len(problems)
                    if len(examples) < 20:
                        examples.append({"target": name, "violations": problems, "frame_index": index})
                    targets[name] = make_targets(seed)[name]  # start clean so one violation is not counted forever
        if progress and index % 10_000 == 9_999:
            rate = (index + 1) / (time.perf_counter() - started)
            print(f"\r{index + 1:,}/{frames:,} frames  {rate:,.0f} frames/s", end="", file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    for name, target in targets.items():
        stats[name].update(decoded=target.decoded(), rejected=target.rejected(), **target.details(),
                           frames_per_s=round(stats[name]["frames"] / max(stats[name]["seconds"], 1e-9)),
                           max_frame_ms=round(stats[name]["max_frame_ms"], 3), seconds=round(stats[name]["seconds"], 1))
    return {"frames": frames, "seed": seed, "wall_s": round(time.perf_counter() - started, 1),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
            "mutations": by_mutation, "targets": stats, "examples": examples,
            "note": "decoded: messages pymavlink decoded (a fuzzed frame may hold none or several); rejected: "
                    "pymavlink bad-data events (one frame may make several), frames dropped by signing and (vehicle) "
                    "partial frames dropped at the end of a datagram; counts are of the last target instance (a target "
                    "restarts after an invariant violation)"}


def print_table(report: dict) -> None:
    columns = ("frames", "crashes", "hangs", "violations", "decoded", "rejected", "max_frame_ms", "frames_per_s")
    print(f"\nMAVLink receive-path fuzzing: {report['frames']:,} frames, seed {report['seed']}, "
          f"{report['wall_s']} s wall, peak RSS {report['peak_rss_mb']} MB")
    print(f"  {'target':18s}" + "".join(f"{c:>14s}" for c in columns))
    for name, figures in report["targets"].items():
        print(f"  {name:18s}" + "".join(f"{figures[c]:>14,}" if isinstance(figures[c], int) else f"{figures[c]:>14}"
                                        for c in columns))
    print("  mutations: " + ", ".join(f"{kind} {count:,}" for kind, count in report["mutations"].items()))
    for example in report["examples"][:5]:
        print(f"  example: {example}")
    print("\nSigning attacks on a signed vehicle (an ARM command each):")
    for attack, figures in report["signing_attacks"].items():
        print(f"  {attack:20s} tried {figures['tried']:6,}  rejected {figures['rejected']:6,} "
              f"({figures['share_rejected']:.1%})  took effect {figures['took_effect']}")


def main() -> int:
    from common import results_file, write_report

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=1_000_000, help="fuzzed frames (each fed to every target)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--attack-trials", type=int, default=1000, help="tries of each signing attack")
    parser.add_argument("--out", default=results_file("fuzz.json"))
    args = parser.parse_args()

    report = run(args.frames, args.seed)
    report["signing_attacks"] = signing_attacks(args.attack_trials, args.seed)
    print_table(report)
    write_report(args.out, {"python": platform.python_version(), **report})
    failures = sum(t["crashes"] + t["hangs"] + t["violations"] for t in report["targets"].values())
    failures += sum(a["took_effect"] + a["tried"] - a["rejected"] for a in report["signing_attacks"].values())
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
