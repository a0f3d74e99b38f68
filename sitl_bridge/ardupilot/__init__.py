"""The ArduPilot Copter personality of the simulated vehicle: its modes, GUIDED targets, AUTO, the failsafes, the
parameter fences, its parameters and ArduPilot's side of the mission protocol
(:class:`sitl_bridge.ardupilot.autopilot.ArduCopter`).
"""
