"""Before arming: what the autopilot does by itself if the companion computer goes silent during the search.

The runner flies the search from the companion computer. If that computer stops (a crash, a power cut, its serial
link to the autopilot broken), the runner's own failsafes stop with it, and what happens next is the autopilot's
configuration alone. With both autopilots' defaults the drone then hovers until its battery is empty:

* **PX4**: the offboard-loss failsafe (COM_OBL_RC_ACT, default 0: Position, which without RC falls back to Hold;
  ``failsafe.cpp`` ``fromOffboardLossActParam``) holds it where it is, and the battery failsafe (COM_LOW_BAT_ACT,
  default 0) only warns (``fromBatteryWarningActParam``). PX4 comes home by itself if COM_OBL_RC_ACT is 3 (Return)
  or COM_LOW_BAT_ACT is 3 (Return at critical, Land at emergency); it comes down where it is with 4 (Land) or 2.
  Its remaining-flight-time failsafe (COM_FLTT_LOW_ACT, default 3 Return) needs a flight-time estimate from a
  configured battery capacity, which the runner cannot see, so it is not counted.
* **ArduPilot Copter**: GUIDED stops after GUID_TIMEOUT and hovers, in GUIDED. The GCS failsafe (FS_GCS_ENABLE,
  default 0) only counts heartbeats from SYSID_MYGCS, so it acts on the companion's silence only if SYSID_MYGCS is
  the companion's system id; the battery failsafe acts if BATT_FS_LOW_ACT (or BATT_FS_CRT_ACT) is set together with
  a threshold (BATT_LOW_VOLT / BATT_LOW_MAH, BATT_CRT_VOLT / BATT_CRT_MAH; ``AP_BattMonitor``), all 0 = off by
  default except BATT_LOW_VOLT (10.5 V) whose action is 0 (none).

The runner reads these parameters with the fence's and records what it found; if nothing would end the flight,
it warns, naming the setting that would (``judge_companion_loss``). A warning, not a refusal: it is each
autopilot's default, and a pilot on a ground station can take over.
"""
from __future__ import annotations

import math

PX4_PARAMS = ("COM_OBL_RC_ACT", "COM_LOW_BAT_ACT")
ARDUPILOT_REQUIRED = ("FS_GCS_ENABLE", "SYSID_MYGCS", "BATT_MONITOR")
ARDUPILOT_BATTERY = ("BATT_FS_LOW_ACT", "BATT_LOW_VOLT", "BATT_LOW_MAH", "BATT_FS_CRT_ACT", "BATT_CRT_VOLT",
                     "BATT_CRT_MAH")  # hidden while BATT_MONITOR is 0 (AP_PARAM_FLAG_ENABLE)
PX4_OFFBOARD_LOSS = {0: "holds (Position, Hold without RC)", 1: "holds (Altitude)", 2: "holds (Stabilized)",
                     3: "returns home", 4: "lands where it is", 5: "holds (Hold)", 6: "cuts its motors (Terminate)",
                     7: "disarms"}
PX4_BATTERY = {0: "only warns", 2: "lands where it is at critical charge",
               3: "returns home at critical charge, lands at emergency"}
ARDUPILOT_ACTIONS = {1: "lands", 2: "returns home", 3: "returns home (SmartRTL or RTL)",
                     4: "returns home (SmartRTL) or lands", 5: "cuts its motors", 6: "lands (DO_LAND_START) or returns",
                     7: "brakes, then lands"}
ENDS_THE_FLIGHT_PX4_OBL = {3, 4}  # Return, Land; Terminate and Disarm end it by falling
ENDS_THE_FLIGHT_PX4_BATTERY = {2, 3}


def companion_loss_params(autopilot: str, read: dict[str, float] | None = None) -> tuple[str, ...]:
    """The parameters to read for an autopilot flavour's name ("PX4" or "ArduPilot Copter"). ``read``: what has
    been read so far; ArduPilot's battery ones are then wanted only once BATT_MONITOR is read and not 0, because
    BATT_MONITOR 0 hides them (AP_BattMonitor_Params.cpp: MONITOR carries AP_PARAM_FLAG_ENABLE), so waiting for
    them would wait for nothing. Without ``read``: all that may exist."""
    if autopilot == "PX4":
        return PX4_PARAMS
    if read is not None and not read.get("BATT_MONITOR"):
        return ARDUPILOT_REQUIRED
    return ARDUPILOT_REQUIRED + ARDUPILOT_BATTERY


def judge_companion_loss(autopilot: str, params: dict[str, float],
                         companion_system_id: int | None) -> tuple[dict, str | None]:
    """(the record for the mission report, a warning or None). ``params`` holds ``companion_loss_params``;
    ``companion_system_id``: the runner's MAVLink system id (None: unknown, ArduPilot's GCS failsafe not counted).
    ArduPilot with BATT_MONITOR 0 (or its BATT_* missing) has no battery failsafe."""
    value = {name: int(params[name]) if math.isfinite(params[name]) else None for name in params}
    if autopilot == "PX4":
        obl, battery = value["COM_OBL_RC_ACT"], value["COM_LOW_BAT_ACT"]
        steps = [f"offboard loss: {PX4_OFFBOARD_LOSS.get(obl, f'COM_OBL_RC_ACT {obl}')} (COM_OBL_RC_ACT {obl})",
                 f"battery: {PX4_BATTERY.get(battery, f'COM_LOW_BAT_ACT {battery}')} (COM_LOW_BAT_ACT {battery})"]
        ends = obl in ENDS_THE_FLIGHT_PX4_OBL or battery in ENDS_THE_FLIGHT_PX4_BATTERY
        fix = "set COM_OBL_RC_ACT=3 (Return) or COM_LOW_BAT_ACT=3 (Return at critical charge)"
    else:
        gcs, mygcs = value["FS_GCS_ENABLE"], value["SYSID_MYGCS"]
        gcs_counts = bool(gcs) and companion_system_id is not None and mygcs == companion_system_id
        steps = [f"GCS failsafe: FS_GCS_ENABLE {gcs}, SYSID_MYGCS {mygcs} "
                 + ("(this computer: it " + ARDUPILOT_ACTIONS.get(gcs, "acts") + ")" if gcs_counts
                    else "(does not act on this computer's silence)")]
        battery_acts, monitored = False, bool(value.get("BATT_MONITOR", 1))
        for level, action, thresholds in (("low", "BATT_FS_LOW_ACT", ("BATT_LOW_VOLT", "BATT_LOW_MAH")),
                                          ("critical", "BATT_FS_CRT_ACT", ("BATT_CRT_VOLT", "BATT_CRT_MAH"))):
            armed_threshold = any((params.get(name) or 0) > 0 for name in thresholds)
            acts = monitored and value.get(action) not in (None, 0, 5) and armed_threshold
            battery_acts |= acts
            setting = f"{action} {value[action]}" if monitored and action in value else "no battery monitor"
            done = ARDUPILOT_ACTIONS.get(value.get(action), "nothing") if acts else "nothing"
            steps.append(f"{level} battery: {done} ({setting})")
        ends = gcs_counts or battery_acts
        fix = ("set BATT_FS_LOW_ACT=2 (RTL at BATT_LOW_VOLT), or FS_GCS_ENABLE=1 with SYSID_MYGCS="
               f"{companion_system_id if companion_system_id is not None else 'this computer'}")
    record = {"checked": True, "ends_the_flight": ends, "steps": steps, "params": value}
    if ends:
        return record, None
    return record, (f"if this computer goes silent during the search, {autopilot} hovers until its battery is empty "
                    f"({'; '.join(steps)}): {fix}")
